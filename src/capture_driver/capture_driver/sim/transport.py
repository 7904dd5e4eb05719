"""Capture simulator: one connection's byte stream, and the model served on TCP and a pty."""

from __future__ import annotations

from gimbal_driver_common.sim_control import (
    ControlError,
    SimControl,
    control_request,
    control_state,
)
from gimbal_driver_common.sim_requests import LateReplies
from gimbal_driver_common.sim_server import PtySimServer, TcpSimServer

from ..protocol import BY_OPCODE, COMMANDS, Frame, ReplyByte, ReplyCode, StreamDecoder
from .axis import FAULTS, SYSTEM_FAULTS
from .model import PedestalModel


class CaptureSession:
    """One connection: byte parsing, the TCP greeting and reply generation.

    The reply to a delayed command (``delay``), an ACK byte or a data packet alike, waits in
    :attr:`late` until the server's poll writes it on this connection, whole, after the
    replies to the requests that came meanwhile: an ACK carries no opcode, so the host sees
    it as the answer to whatever it asked last, as from a real controller that answers late.
    """

    def __init__(self, model: PedestalModel, greet: bool, each_reply: bool = False) -> None:
        self.model = model
        self.each_reply = each_reply  # on_bytes gives the replies one by one (--nagle)
        self.decoder = StreamDecoder()
        self.connected = False
        self._greeting = COMMANDS['COM_Connect'].encode() if greet else b''
        self.late: LateReplies[bytes] = LateReplies()

    def poll(self) -> bytes:
        # the server calls this every few ms while its reader runs: the reader is listening
        self.model.listened()
        greeting, self._greeting = self._greeting, b''
        return greeting + b''.join(self.late.due())

    def on_bytes(self, data: bytes) -> bytes | list[bytes]:
        replies: list[bytes] = []
        handled = False
        for item in self.decoder.feed(data):
            if isinstance(item, Frame):
                if handled and self.model.one_request_per_read:
                    continue
                handled = True
                reply = bytes(self.model.handle(item, self))
                command = BY_OPCODE.get(item.opcode)
                seconds = self.model.request_faults.delay_of(command.name) if command else 0.0
                if seconds and reply:
                    self.late.hold([reply], seconds)
                else:
                    replies.append(reply)
            elif isinstance(item, ReplyByte):
                continue  # the host never sends reply bytes; ignore
            elif item.reason == 'checksum mismatch':
                replies.append(bytes([ReplyCode.WRONG_CHECKSUM]))  # 2.1: bad checksum: 0xF6
        return replies if self.each_reply else b''.join(replies)

    def on_disconnect(self) -> None:
        self.connected = False


class CaptureSimulator:
    """The model plus its TCP and/or pty servers."""

    def __init__(self, model: PedestalModel | None = None, tcp_port: int | None = 0,
                 pty: bool = False, pty_link: str | None = None, nagle: bool = False) -> None:
        self.model = model or PedestalModel()
        self.tcp = (TcpSimServer(lambda: CaptureSession(self.model, greet=True, each_reply=nagle),
                                 port=tcp_port, nagle=nagle)
                    if tcp_port is not None else None)
        self.pty = (PtySimServer(lambda: CaptureSession(self.model, greet=False), pty_link)
                    if pty else None)
        self._controls: SimControl | None = None

    def start(self) -> CaptureSimulator:
        self.model.start()
        for server in (self.tcp, self.pty):
            if server is not None:
                server.start()
        return self

    def stop(self) -> None:
        for server in (self.tcp, self.pty):
            if server is not None:
                server.stop()
        self.model.stop()

    def __enter__(self) -> CaptureSimulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def drop_link(self, offline_for: float = 0.0) -> None:
        for server in (self.tcp, self.pty):
            if server is not None:
                server.drop_link(offline_for)

    def inject_garbage(self, data: bytes) -> None:
        for server in (self.tcp, self.pty):
            if server is not None:
                server.inject(data)

    def set_silent(self, silent: bool) -> None:
        for server in (self.tcp, self.pty):
            if server is not None:
                server.set_silent(silent)

    def control(self, line: str) -> str:
        """Run one control request (the shared verbs plus Capture's); return the answer."""
        return self.controls.execute(line)

    @property
    def controls(self) -> SimControl:
        if self._controls is None:
            self._controls = self._make_controls()
        return self._controls

    def _make_controls(self) -> SimControl:
        model = self.model
        links = [server for server in (self.tcp, self.pty) if server is not None]
        control = SimControl('capture_sim', self.state, links=links, nack=self._nack,
                             fault=self._fault, fault_names=(*FAULTS, *SYSTEM_FAULTS),
                             clear_device=model.clear_injected,
                             axes=lambda: model.axes.values(),
                             request_names=lambda: COMMANDS,
                             request_faults=model.request_faults)
        control.add_verb('lose', lambda a: model.lose_replies(int(a[0]) if a else 1),
                         'lose [COUNT]')
        control.add_verb('unknown', lambda a: self._toggle(model.unknown_opcodes, a),
                         'unknown COMMAND [on|off]')
        control.add_verb('wrong', lambda a: self._toggle(model.wrong_kind_opcodes, a),
                         'wrong COMMAND [on|off]  (answer it with the other kind of reply)')
        control.add_verb('gps', model.set_gps_from_console,
                         'gps LAT LON ALT HEADING | gps nofix: the GPS position (deg, deg, m) '
                         'and heading (deg clockwise from north), or no fix')
        control.add_verb('inserted', model.set_inserted_from_console,
                         'inserted LAT LON ALT HEADING | inserted off: the user-inserted '
                         'position and heading with the override flag set, or the flag off')
        control.add_verb('pose', lambda a: model.set_pose(int(a[0]), float(a[1])),
                         'pose AXIS DEG')
        control.add_verb('detect', lambda a: model.set_target_detected(
            int(a[0]), a[1].lower() in ('1', 'on', 'true')), 'detect CAMERA on|off')
        control.add_verb('dio', self._dio, 'dio N 0|1')
        control.add_verb('count', self._count, 'count COMMAND')
        return control

    def _nack(self, args: list[str]) -> str | None:
        """``nack on [HEXCODE]`` / ``nack off`` / ``nack COMMAND|* [COUNT] [HEXCODE]``."""
        model, word = self.model, args[0]
        if word.lower() in ('on', 'off'):
            code = ReplyCode(int(args[1], 16)) if len(args) > 1 else ReplyCode.EXECUTION_ERROR
            with model.lock:
                model.nack_all = code if word.lower() == 'on' else None
                if word.lower() == 'off':
                    model.nack_queue.clear()
            return None
        opcode = None if word == '*' else COMMANDS[word].opcode
        count = int(args[1]) if len(args) > 1 else 1
        code = ReplyCode(int(args[2], 16)) if len(args) > 2 else ReplyCode.EXECUTION_ERROR
        model.nack_next(code, opcode, count)
        return None

    def _fault(self, args: list[str]) -> str | None:
        """``fault NAME [AXIS]``: an axis fault of FAULTS (MER bits latched, default axis 1),
        a CSR flag name, or ``fault BITS [AXIS]`` with a MER bit mask."""
        model, name = self.model, args[0]
        if name in SYSTEM_FAULTS:
            model.inject_system_fault(name)
            return None
        axis = int(args[1]) if len(args) > 1 else 1
        if axis not in model.axes:
            raise ControlError(f'no axis {axis}; axes {sorted(model.axes)}')
        if name in FAULTS:
            model.inject_fault(axis, name)
            return None
        bits = int(name, 0)
        with model.lock:
            model.axes[axis].mer_latched |= bits
            model.axes[axis].halt()
            model.scan = None
        return None

    def _toggle(self, opcodes: set[int], args: list[str]) -> None:
        """``COMMAND [on|off]``: add or remove the command's opcode in one of the model's
        opcode sets (unknown, wrong kind of reply)."""
        opcode = COMMANDS[args[0]].opcode
        with self.model.lock:
            if len(args) > 1 and args[1].lower() in ('off', '0', 'false'):
                opcodes.discard(opcode)
            else:
                opcodes.add(opcode)

    def _dio(self, args: list[str]) -> None:
        with self.model.lock:
            self.model.stored[('COM_digitalio', int(args[0]))] = int(
                args[1].lower() in ('1', 'on', 'true'))

    def _count(self, args: list[str]) -> str:
        opcode = COMMANDS[args[0]].opcode
        with self.model.lock:
            return str(self.model.request_counts[opcode])

    def state(self) -> dict:
        """The ``state`` answer: axes (load degrees) and the controller's modes."""
        model = self.model
        with model.lock:
            return {
                'axes': {n: {**a.snapshot(), 'axis_on': a.axis_on, 'homing': a.homing,
                             'faulted': a.faulted} for n, a in model.axes.items()},
                'scanning': model.scan is not None,
                'preset_looping': bool(model.preset_looping),
                'emergency_stop': model.emergency_stop,
                'presets': sorted(model.presets),
                'target_looping': bool(model.target_looping),
                'tracker_mode': model.tracker_mode,
                'gyro_drift': model.gyro_drift,
                'digital_io': {n: model.stored.get(('COM_digitalio', n), 0)
                               for n in range(1, 7)},
                'lrf_measuring': bool(model.stored.get(('LRF_measuring', 0))),
                'keepalive': model.keepalive_on,
                'requests': model.request_total,
                'requests_by_command': {
                    BY_OPCODE[opcode].name if opcode in BY_OPCODE else f'0x{opcode:04X}': count
                    for opcode, count in model.request_counts.items()},
                'connections': self.tcp.connections if self.tcp else 0,
                'nack_all': model.nack_all is not None,
                'ack_unknown': model.ack_unknown,
                'known_commands': None if model.known_opcodes is None else sorted(
                    BY_OPCODE[opcode].name for opcode in model.known_opcodes),
            }


#: one request to a running capture_sim's TCP console (the shared protocol)
control = control_request
#: its ``state`` answer as a dict
console_state = control_state
