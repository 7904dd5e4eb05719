"""kOS simulator transports: a TCP or USB session, the in-process HID device, and the TCP
simulator with discovery and its console."""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
import time

from gimbal_driver_common.sim_control import ControlServer, SimControl, control_request
from gimbal_driver_common.sim_requests import LateReplies
from gimbal_driver_common.sim_server import TcpSimServer

from ..protocol import (
    DISCOVERY_PERIOD_S,
    AuxInputStatus,
    ErrorCode,
    ErrorStatus,
    FrameParser,
    ProtocolError,
    UnsupportedMessage,
    decode,
)
from ..protocol.usb import REPORT_SIZE, USB_KEEPALIVE, ReportReassembler, encode_reports
from .handlers import REQUESTS
from .model import SimulatedRig
from .motor import SimSettings, _Playback

LOG = logging.getLogger('kessler_kos_sim')


class KosSession:
    """One TCP connection or USB HID link: framing, lock state, keep-alive, reply queue.

    The replies to a delayed request (``delay``) wait in :attr:`late`; :meth:`poll` (the
    server's, or the HID device's read) sends them when due, whole, between other messages.
    """

    def __init__(self, device: SimulatedRig, usb: bool = False) -> None:
        self.device = device
        self.usb = usb
        self.parser = FrameParser()
        self.unlocked = usb            # USB has no password messages
        self.usb_keepalives = 0
        self.outbox: list[bytes] = []
        self.last_rx = time.monotonic()
        self.malformed = 0
        self.late: LateReplies[bytes] = LateReplies()
        with device.lock:
            device.sessions.append(self)

    def on_bytes(self, data: bytes) -> bytes:
        self.last_rx = time.monotonic()
        device = self.device
        device.advance()
        with device.lock:
            for frame in self.parser.feed(data):
                if self.usb and frame == USB_KEEPALIVE:
                    self.usb_keepalives += 1
                    continue
                try:
                    message = decode(frame)
                except ProtocolError as exc:
                    self.malformed += 1
                    LOG.info('malformed frame (%s); answering UnsupportedMessage', exc)
                    if self.unlocked:
                        self.outbox.append(UnsupportedMessage(frame[:64]).encode())
                    continue
                answered = len(self.outbox)
                device.handle(message, frame, self)
                seconds = device.request_faults.delay_of(type(message).__name__)
                if seconds and len(self.outbox) > answered:
                    self.late.hold(self.outbox[answered:], seconds)
                    del self.outbox[answered:]
            return self._drain()

    def poll(self) -> bytes:
        device = self.device
        if time.monotonic() - self.last_rx > device.settings.keepalive_timeout:
            LOG.info('no message for %.1f s: dropping the connection (keep-alive)',
                     device.settings.keepalive_timeout)
            raise ConnectionAbortedError('kOS keep-alive expired')
        if device.reboot_requested:
            raise ConnectionAbortedError('device reboot')
        device.advance()
        with device.lock:
            return self._drain()

    def _drain(self) -> bytes:
        data = b''.join(self.outbox + self.late.due())
        self.outbox.clear()
        return data

    def on_disconnect(self) -> None:
        with self.device.lock:
            if self in self.device.sessions:
                self.device.sessions.remove(self)


class SimHidDevice:
    """The simulated device seen through USB HID, with the methods of `hid.device`.

    `write` takes output reports (report ID 0x01 + message bytes, zero padded) and feeds the
    reassembled kOS bytes to a USB session of the shared `SimulatedRig`; `read` returns one
    input report (report ID first, padded to `report_size`) per call, polling the session
    for notifications while it waits. A session silent for the keep-alive timeout, or a
    device unplugged with `unplug()`, makes `read`/`write` raise OSError like hidapi does.
    """

    def __init__(self, device: SimulatedRig, report_size: int = REPORT_SIZE) -> None:
        self.device = device
        self.report_size = report_size
        self.session: KosSession | None = None
        self.reports_written: list[bytes] = []   # raw output reports, for inspection
        self.reports_read: list[bytes] = []
        self._reassembler = ReportReassembler()
        self._parser = FrameParser()
        self._inbox: list[bytes] = []
        self._lock = threading.Lock()
        self._unplugged = False

    # -- hid.device methods
    def open(self, vendor_id: int = 0, product_id: int = 0,
             serial_number: str | None = None) -> None:
        self._open()

    def open_path(self, path: bytes) -> None:
        self._open()

    def _open(self) -> None:
        if self._unplugged:
            raise OSError('open failed')
        self.close()
        self.session = KosSession(self.device, usb=True)

    def close(self) -> None:
        session, self.session = self.session, None
        if session is not None:
            session.on_disconnect()
        self._reassembler.reset()
        self._parser.reset()
        self._inbox.clear()

    def write(self, buff) -> int:
        report = bytes(buff)
        session = self._session()
        with self._lock:
            self.reports_written.append(report)
            self._queue(session.on_bytes(self._reassembler.feed(report)))
        return len(report)

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        deadline = time.monotonic() + timeout_ms / 1000.0
        while True:
            session = self._session()
            with self._lock:
                if not self._inbox:
                    try:
                        self._queue(session.poll())
                    except ConnectionAbortedError as exc:
                        self.close()
                        raise OSError(f'read error ({exc})') from exc
                if self._inbox:
                    report = self._inbox.pop(0)
                    self.reports_read.append(report)
                    return list(report[:max_length])
            if time.monotonic() >= deadline:
                return []
            time.sleep(0.002)

    # -- test helpers
    def unplug(self) -> None:
        """The cable is pulled: reads and writes fail, open fails until `plug_in()`."""
        self._unplugged = True
        self.close()

    def plug_in(self) -> None:
        self._unplugged = False

    def inject_report(self, report: bytes) -> None:
        """Queue a raw input report (foreign report IDs, garbage)."""
        with self._lock:
            self._inbox.append(bytes(report))

    def _session(self) -> KosSession:
        if self.session is None:
            raise OSError('read error' if self._unplugged else 'device not open')
        return self.session

    def _queue(self, data: bytes) -> None:
        for frame in self._parser.feed(data):
            self._inbox.extend(encode_reports(frame, self.report_size))


class KosSimulator:
    """Device + TCP server + discovery beacon + optional control port."""

    def __init__(self, settings: SimSettings, port: int = 0, discovery_port: int = 0,
                 control_port: int | None = None) -> None:
        self.device = SimulatedRig(settings)
        self.server = TcpSimServer(lambda: KosSession(self.device), port=port)
        self.discovery_port = discovery_port
        self.control_port_requested = control_port
        self.control_port = 0
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._control_server: ControlServer | None = None
        self.controls = self._make_controls()

    @property
    def port(self) -> int:
        return self.server.port

    def start(self) -> KosSimulator:
        self.server.start()
        self._spawn(self._background, 'kos-sim-background')
        if self.control_port_requested is not None:
            self._control_server = ControlServer(self.controls,
                                                 self.control_port_requested).start()
            self.control_port = self._control_server.port
        return self

    def stop(self) -> None:
        self._stop.set()
        self.server.stop()
        if self._control_server is not None:
            self._control_server.stop()
        for thread in self._threads:
            thread.join(timeout=2.0)

    def _spawn(self, target, name: str) -> None:
        thread = threading.Thread(target=target, name=name, daemon=True)
        thread.start()
        self._threads.append(thread)

    def _background(self) -> None:
        """Keep physics running without clients, beacon NetworkInfo, handle reboots."""
        next_beacon = time.monotonic()
        beacon = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            while not self._stop.wait(0.02):
                self.device.advance()
                if self.device.reboot_requested:
                    self.server.drop_link()
                    with self.device.lock:
                        self.device.reboot_requested = False
                        self.device.playback = _Playback()
                now = time.monotonic()
                if self.discovery_port and now >= next_beacon:
                    next_beacon = now + DISCOVERY_PERIOD_S / max(self.device.settings.time_scale,
                                                                 1.0)
                    if self.server.client_count == 0:
                        data = self.device.network_info().encode()
                        # Loopback only: never the limited broadcast the document describes.
                        with contextlib.suppress(OSError):
                            beacon.sendto(data, ('127.0.0.1', self.discovery_port))
        finally:
            beacon.close()

    # ------------------------------------------------------------- control verbs
    def command(self, line: str) -> str:
        """Run one control request (shared verbs plus kOS's own); return the answer line."""
        return self.controls.execute(line)

    def _make_controls(self) -> SimControl:
        device = self.device
        control = SimControl(
            'kessler_kos_sim', self.state, links=[self.server],
            no_nack='kOS answers a bad request with ErrorStatus (see fault and error), '
                    'it has no negative acknowledge',
            fault=self._fault, fault_names=('axis',), clear_device=self._clear_injected,
            axes=lambda: device.motors.values(), request_names=lambda: REQUESTS,
            request_faults=device.request_faults)
        control.add_verb('offline', lambda a: device.set_motor_online(int(a[0]), False),
                         'offline MOTOR')
        control.add_verb('online', lambda a: device.set_motor_online(int(a[0]), True),
                         'online MOTOR')
        control.add_verb('error', self._error, 'error CODE [MOTOR] (ErrorStatus, no reset)')
        control.add_verb('aux', self._aux, 'aux BITS (AuxInputStatus)')
        return control

    def _fault(self, args: list[str]) -> None:
        """``fault axis MOTOR`` or ``fault CODE MOTOR``: ErrorStatus with axis reset."""
        code = ErrorCode.AXIS_FAULT if args[0].lower() == 'axis' else int(args[0], 0)
        self.device.inject_axis_fault(int(args[1]) if len(args) > 1 else 1, code)

    def _error(self, args: list[str]) -> None:
        with self.device.lock:
            self.device.broadcast(ErrorStatus(int(args[0]), int(args[1]) if len(args) > 1
                                              else 0))

    def _aux(self, args: list[str]) -> None:
        bits = int(args[0], 0)
        with self.device.lock:
            self.device.aux_input = bits
            self.device.broadcast(AuxInputStatus(bits))

    def _clear_injected(self) -> None:
        for address, motor in self.device.motors.items():
            if not motor.online:
                self.device.set_motor_online(address, True)

    def state(self) -> dict:
        """The ``state`` answer: motors (rotations) by role, playback phase, photos."""
        device = self.device
        with device.lock:
            return {
                'axes': {m.role: {**m.snapshot(), 'address': m.address, 'begin': m.begin,
                                  'end': m.end, 'online': m.online}
                         for m in device.motors.values()},
                'phase': device.playback.phase, 'photos': device.photos_taken,
                'clients': self.server.client_count, 'led': list(device.led),
                'aux_input': device.aux_input,
            }


#: one request to a running kessler_kos_sim's TCP console (the shared protocol)
control = control_request
