"""Kessler kOS device session over TCP or USB HID (no ROS).

Responsibilities: discovery (listen for NetworkInfo datagrams), the initialisation sequence
(DeviceInfo, UserPassword, MotorInfo, DeviceGUID), request/response matching, notification
handling (motor, playback, error state, aux inputs), the 10 s keep-alive, periodic state
polling and checked commands (limits are checked before any byte is sent). Reconnecting is not
the client's job: the controller's supervisor (gimbal_driver_common.controller) calls
:meth:`KosClient.connect` again after a loss, which the client reports through `connected`
and `last_error_text`. Over USB (`usb=UsbTarget(...)`) the link is a
:class:`~.usb_link.HidStream` (report framing and the 4 s USB keep-alive) and no password
message is sent: the document's USB notes say UserPassword and DevicePassword are "not
required or supported".

Design notes:
- Set messages and actions have no reply. Where the caller needs to know the outcome the client
  follows them with a Get as a *barrier*: the device handles messages in order, so any
  ErrorStatus caused by the action arrives before the barrier's response.
- Responses are matched by MessageID with a per-id sequence counter, so unsolicited responses
  (the device sends NetworkInfo over TCP while connected, polls overlap) are harmless.
- The password is never logged or put in exception text; DeviceInfo carries the device password
  and its repr hides it.
"""

from __future__ import annotations

import contextlib
import logging
import math
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from gimbal_driver_common import errors
from gimbal_driver_common.transport import ByteStream, TcpStream, TransportError

from .protocol import (
    ALL_MOTORS,
    DEFAULT_TCP_PORT,
    HEADER_SIZE,
    KEEPALIVE_PERIOD_S,
    PLAYBACK_RUNNING_STATES,
    REPORT_SIZE,
    UNCALIBRATED_TARGET,
    USB_KEEPALIVE_PERIOD_S,
    AuxInputStatus,
    BumpPositionSpeedAcceleration,
    DeviceGuid,
    DeviceInfo,
    ErrorCode,
    ErrorStatus,
    FrameParser,
    GetDeviceGuid,
    GetDeviceInfo,
    GetLedStatus,
    GetMotorInfo,
    GetNetworkInfo,
    GetSoftwareId,
    GetTrajectoryData,
    LedState,
    LedStatus,
    MarkBeginPosition,
    MarkEndPosition,
    Message,
    MessageId,
    MotorCalibrated,
    MotorInfo,
    MotorPosition,
    MotorStatus,
    NetworkInfo,
    PlaybackState,
    PlaybackStatus,
    ProtocolError,
    RapidToFirstKeyFrame,
    ResetAxis,
    SetPositionSpeedAcceleration,
    SetupPlayback,
    SoftwareId,
    StartPlayback,
    StopPlayback,
    TakePicture,
    Trajectory,
    TrajectoryData,
    UnknownMessage,
    UnsupportedMessage,
    UserPassword,
    decode,
    describe_error,
    unpack_header,
    validate,
)
from .protocol.trajectory import AxisLimits
from .usb_link import HidDevice, HidStream, UsbTarget

LOG = logging.getLogger('kessler_kos_driver.client')


class KosError(errors.GimbalError):
    """Base of the client's errors (in the shared hierarchy); messages say what to do."""


class NotConnected(KosError, errors.LinkError):
    """No link (unreachable, no discovery datagram, USB device missing) or the link dropped."""


class DeviceTimeout(KosError, errors.DeviceTimeout):
    """The device did not answer a Get in time."""


class MessageUnsupported(KosError, errors.Unsupported):
    """The device answered a request with UnsupportedMessage: it answered, it is not silent."""


class PasswordRejected(KosError, errors.DeviceRefused):
    """The password does not match (checked locally) or the device locked us out."""


class CommandRejected(KosError, errors.DeviceRefused):
    """A command refused before sending (limits, unknown motor) or by the device."""


@dataclass
class MotorState:
    address: int
    position: float = 0.0          # rotations
    velocity: float = 0.0          # rotations/s (estimated from successive reports)
    begin_position: float = 0.0
    end_position: float = 0.0
    max_setup_speed: float = 0.0
    max_move_speed: float = 0.0
    max_acceleration: float = 0.0
    is_fiz: bool = False
    online: bool = True
    stamp: float = 0.0             # time.time() of the last position report
    last_error: int | None = None

    @property
    def calibrated(self) -> bool:
        return self.end_position != 0.0

    def travel(self) -> tuple[float, float]:
        """Allowed target range in rotations."""
        if self.calibrated:
            return (min(self.begin_position, self.end_position),
                    max(self.begin_position, self.end_position))
        return -UNCALIBRATED_TARGET, UNCALIBRATED_TARGET

    def limits(self) -> AxisLimits:
        return AxisLimits(self.begin_position, self.end_position, self.max_move_speed,
                          self.max_acceleration)


@dataclass
class PlaybackInfo:
    status: int = PlaybackState.NO_MOVE
    elapsed: float = 0.0
    photo_count: int = 0
    positions: dict[int, float] = field(default_factory=dict)
    loaded: bool = False           # TrajectoryData accepted and not yet consumed by FullStop
    set_up: bool = False
    history: list[int] = field(default_factory=list)   # statuses since the last load


@dataclass
class ErrorEvent:
    code: int
    motor_address: int
    description: str
    stamp: float


def discover(discovery_port: int, timeout: float, bind_address: str = '0.0.0.0') -> str:
    """Listen for NetworkInfo datagrams; return the first device's IP address as text."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((bind_address, discovery_port))
    except OSError as exc:
        sock.close()
        raise NotConnected(f'cannot listen for discovery on UDP {bind_address}:'
                           f'{discovery_port}: {exc}') from exc
    deadline = time.monotonic() + timeout
    try:
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise NotConnected(
                    f'no kOS device announced itself on UDP port {discovery_port} within '
                    f'{timeout:.1f} s; set the host parameter or check the network')
            sock.settimeout(remaining)
            try:
                data, sender = sock.recvfrom(2048)
            except TimeoutError:
                continue
            for frame in FrameParser().feed(data):
                with contextlib.suppress(ProtocolError):
                    message = decode(frame)
                    if isinstance(message, NetworkInfo):
                        # The datagram's source is what we can reach; the payload may carry
                        # a private address behind NAT.
                        return message.ip_text if message.ip_address else sender[0]
    finally:
        sock.close()


class KosClient:
    """A session with one kOS device. Thread-safe; callbacks run on the reader thread."""

    def __init__(
        self,
        host: str = '',
        port: int = DEFAULT_TCP_PORT,
        password: str = '',
        discovery_port: int = DEFAULT_TCP_PORT,
        discovery_timeout: float = 10.0,
        discovery_bind: str = '0.0.0.0',
        connect_timeout: float = 2.0,
        reply_timeout: float = 2.0,
        keepalive_period: float = KEEPALIVE_PERIOD_S,
        poll_period: float = 0.1,
        stream_factory: Callable[[str, int], ByteStream] | None = None,
        usb: UsbTarget | None = None,
        usb_report_size: int = REPORT_SIZE,
        usb_keepalive_period: float = USB_KEEPALIVE_PERIOD_S,
        usb_device_factory: Callable[[], HidDevice] | None = None,
    ) -> None:
        self.host = host
        self.port = int(port)
        self._password = password
        self.discovery_port = discovery_port
        self.discovery_timeout = discovery_timeout
        self.discovery_bind = discovery_bind
        self.connect_timeout = connect_timeout
        self.reply_timeout = reply_timeout
        self.keepalive_period = keepalive_period
        self.poll_period = poll_period
        self.usb = usb
        if usb is not None:
            usb.check()
            self._stream_factory = stream_factory or (lambda _h, _p: HidStream(
                usb, usb_keepalive_period, usb_report_size, usb_device_factory))
        else:
            self._stream_factory = stream_factory or (
                lambda h, p: TcpStream(h, p, connect_timeout))
        self._stream: ByteStream | None = None
        self._connected_host = ''
        self._lock = threading.RLock()
        self._cond = threading.Condition(self._lock)
        self._seq: dict[int, int] = {}
        #: MessageID -> UnsupportedMessage replies naming it (the offending message's header)
        self._refused: dict[int, int] = {}
        self._latest: dict[int, Message] = {}
        self._motor_parts: list = []
        self._request_lock = threading.Lock()
        self._last_tx = 0.0
        self._last_rx = 0.0
        self._unanswered_since: float | None = None   # first send after the last receive
        self.silence_timeout = max(2.0 * reply_timeout, 1.0)
        self._reader: threading.Thread | None = None
        self._ticker: threading.Thread | None = None
        self._session_stop = threading.Event()
        self.connected = False
        self.device_info: DeviceInfo | None = None
        self.guid = ''
        self.motors: dict[int, MotorState] = {}
        self.playback = PlaybackInfo()
        self.errors: deque[ErrorEvent] = deque(maxlen=50)
        self.error_total = 0           # ErrorStatus notifications received so far
        self.malformed_frames = 0
        self.unsupported_replies = 0
        self.last_error_text = ''      # why the link was lost (for the supervisor's reason)
        self.on_playback: Callable[[PlaybackStatus], None] | None = None
        self.on_error: Callable[[ErrorEvent], None] | None = None
        self.on_motor_update: Callable[[], None] | None = None
        self.aux_inputs = 0            # AuxInputStatus bits (DeviceInfo, then notifications)
        self.on_aux_inputs: Callable[[int], None] | None = None

    # ------------------------------------------------------------------ connection
    @property
    def description(self) -> str:
        if self.usb is not None:
            return self.usb.describe()
        host = self._connected_host or self.host or f'discover:udp/{self.discovery_port}'
        return f'tcp://{host}:{self.port}'

    @property
    def usb_dropped_reports(self) -> int:
        """USB input reports dropped (other report IDs, padding-only, no header); 0 on TCP."""
        stream = self._stream
        return stream.dropped_reports if isinstance(stream, HidStream) else 0

    def connect(self) -> None:
        """Open the link and run the initialisation sequence; raises KosError on failure."""
        self.close()
        if self.usb is not None:
            host = ''
        else:
            host = self.host or discover(self.discovery_port, self.discovery_timeout,
                                         self.discovery_bind)
        stream = self._stream_factory(host, self.port)
        try:
            stream.open()
        except TransportError as exc:
            raise NotConnected(str(exc)) from exc
        self._connected_host = host
        with self._lock:
            self._stream = stream
            self._seq.clear()
            self._refused.clear()
            self._latest.clear()
            self._motor_parts = []
            self._session_stop = threading.Event()
            self._unanswered_since = None
        self._reader = threading.Thread(target=self._read_loop, args=(stream,
                                         self._session_stop), name='kos-reader', daemon=True)
        self._reader.start()
        try:
            self._initialise()
        except Exception:
            self.close()
            raise
        self.connected = True
        self._ticker = threading.Thread(target=self._tick_loop, args=(self._session_stop,),
                                        name='kos-keepalive', daemon=True)
        self._ticker.start()
        self.last_error_text = ''
        LOG.info('connected to %s (%s firmware %s, %d motors)', self.description,
                 self.device_info.device_type if self.device_info else '?',
                 self.device_info.firmware if self.device_info else '?', len(self.motors))

    def _initialise(self) -> None:
        """Document "Initialization": DeviceInfo, UserPassword, MotorInfo, DeviceGUID."""
        info = self.request(GetDeviceInfo())
        assert isinstance(info, DeviceInfo)
        self.device_info = info
        with self._lock:
            self.aux_inputs = info.aux_input_status
        if self.usb is not None:   # USB: no password messages
            self.refresh_motors()
            self._finish_initialisation(info)
            return
        if info.device_password != self._password:
            # Compare locally (the device reports its password) so a wrong password never
            # reaches the device; the value itself is never logged.
            raise PasswordRejected(
                'the password parameter does not match the device password (the device '
                'would stay locked); set the correct password')
        errors_before = self.error_total
        self.send(UserPassword(self._password))
        try:
            self.refresh_motors()
        except DeviceTimeout as exc:
            if any(e.code == ErrorCode.LOCKED_OUT for e in self._errors_since(errors_before)):
                raise PasswordRejected('the device rejected the password (ErrorStatus 15, '
                                       'locked out)') from exc
            raise
        self._finish_initialisation(info)

    def _finish_initialisation(self, info: DeviceInfo) -> None:
        guid = self.request(GetDeviceGuid())
        assert isinstance(guid, DeviceGuid)
        self.guid = guid.text
        with self._lock:
            self.playback.status = info.playback_status

    def close(self) -> None:
        """Close the link and end the session's threads (safe to call repeatedly)."""
        self.connected = False
        with self._lock:
            stream, stop = self._stream, self._session_stop
        self._end_session(stream, stop)
        for thread in (self._reader, self._ticker):
            if thread is not None and thread is not threading.current_thread():
                thread.join(timeout=2.0)
        self._reader = self._ticker = None

    # ------------------------------------------------------------------- messaging
    def send(self, message: Message) -> None:
        """Encode (checks ranges) and send one message."""
        data = message.encode()
        with self._lock:
            stream = self._stream
        if stream is None:
            raise NotConnected(f'not connected to {self.description}')
        try:
            stream.write(data)
        except TransportError as exc:
            self._link_lost(str(exc))
            raise NotConnected(f'link to {self.description} lost: {exc}') from exc
        self._last_tx = time.monotonic()
        if self._unanswered_since is None:
            self._unanswered_since = self._last_tx

    def request(self, message: Message, timeout: float | None = None) -> Message:
        """Send a Get and wait for the next complete response with the same MessageID.

        An UnsupportedMessage that carries this MessageID is the device's answer too: it
        raises :class:`MessageUnsupported` at once instead of a "no reply" timeout."""
        message_id = message.MESSAGE_ID
        timeout = self.reply_timeout if timeout is None else timeout
        with self._request_lock:
            with self._lock:
                seq0 = self._seq.get(message_id, 0)
                refused0 = self._refused.get(message_id, 0)
            self.send(message)
            deadline = time.monotonic() + timeout
            with self._cond:
                while self._seq.get(message_id, 0) == seq0:
                    remaining = deadline - time.monotonic()
                    what = type(message).__name__
                    if self._refused.get(message_id, 0) != refused0:
                        raise MessageUnsupported(f'{self.description} answered {what} with '
                                                 'UnsupportedMessage: the device does not '
                                                 'support it')
                    if self._stream is None:   # the link was lost (or closed) meanwhile
                        raise NotConnected(f'link to {self.description} lost while waiting '
                                           f'for the reply to {what}')
                    if remaining <= 0:
                        raise DeviceTimeout(f'no reply to {what} from {self.description} '
                                            f'within {timeout:.1f} s')
                    if self._reader is not None and not self._reader.is_alive():
                        # the peer closed the link during the handshake (before `connected`,
                        # so no link-lost teardown): fail now, not after the reply timeout
                        raise NotConnected(f'link to {self.description} closed while '
                                           f'waiting for the reply to {what}')
                    self._cond.wait(min(remaining, 0.05))
                return self._latest[message_id]

    def barrier(self) -> None:
        """Wait until the device has handled everything sent so far."""
        self.request(GetNetworkInfo(False))

    def _read_loop(self, stream: ByteStream, stop: threading.Event) -> None:
        parser = FrameParser()
        while not stop.is_set():
            try:
                data = stream.read(4096, 0.2)
            except (TransportError, OSError) as exc:
                # OSError: TcpStream.read's settimeout() on a socket closed by another
                # thread raises EBADF outside its own TransportError mapping.
                if not stop.is_set():
                    self._link_lost(str(exc))
                return
            if not data:
                continue
            self._last_rx = time.monotonic()
            self._unanswered_since = None
            before = parser.discarded_bytes
            for frame in parser.feed(data):
                try:
                    message = decode(frame)
                except ProtocolError as exc:
                    self.malformed_frames += 1
                    LOG.warning('ignoring malformed kOS frame: %s', exc)
                    continue
                try:
                    self._dispatch(message)
                except Exception:  # a callback bug must not kill the session
                    LOG.exception('error while handling %s', type(message).__name__)
            if parser.discarded_bytes != before:
                self.malformed_frames += 1
                LOG.warning('skipped %d garbage bytes from %s while resynchronising',
                            parser.discarded_bytes - before, self.description)

    def _link_lost(self, reason: str) -> None:
        if not self.connected:
            return
        self.connected = False
        LOG.warning('kOS link to %s lost: %s', self.description, reason)
        self.last_error_text = f'link lost: {reason}'
        with self._lock:
            stream, stop = self._stream, self._session_stop
        # Not inline: this runs on the session's own threads or a caller's, and closing a
        # HID stream waits for a read in progress.
        threading.Thread(target=self._end_session, args=(stream, stop), name='kos-teardown',
                         daemon=True).start()

    def _end_session(self, stream: ByteStream | None, stop: threading.Event) -> None:
        """End one session: its threads see `stop`, its stream closes. A session opened since
        (the controller reconnects while this runs late) is left alone."""
        stop.set()
        with self._lock:
            if self._stream is stream:
                self._stream = None
            self._cond.notify_all()
        if stream is not None:
            stream.close()

    def _tick_wait(self, next_poll: float) -> float:
        if self.poll_period <= 0:
            return 0.02
        return max(0.0, min(0.02, next_poll - time.monotonic()))

    def _tick_loop(self, stop: threading.Event) -> None:
        """State polling (GetMotorInfo), the keep-alive (GetNetworkInfo when idle) and the
        silent-device check (requests sent, nothing received for silence_timeout)."""
        next_poll = time.monotonic()
        # Wake for the next poll exactly (a fixed 20 ms tick made a 50 ms poll period 60 ms),
        # and at least every 20 ms for the silence and keep-alive checks.
        while not stop.wait(self._tick_wait(next_poll)):
            now = time.monotonic()
            waiting = self._unanswered_since
            if waiting is not None and now - waiting > self.silence_timeout:
                self._link_lost(f'device silent: no reply for {now - waiting:.1f} s')
                return
            try:
                if self.poll_period > 0 and now >= next_poll:
                    next_poll += self.poll_period
                    if next_poll <= now:  # fell behind: do not burst to catch up
                        next_poll = now + self.poll_period
                    self.send(GetMotorInfo())
                elif self.keepalive_period > 0 and now - self._last_tx >= self.keepalive_period:
                    self.send(GetNetworkInfo(False))
            except KosError:
                return

    # --------------------------------------------------------------- notifications
    def _completed(self, message_id: int, message: Message) -> None:
        self._latest[message_id] = message
        self._seq[message_id] = self._seq.get(message_id, 0) + 1
        self._cond.notify_all()

    def _dispatch(self, message: Message) -> None:
        now = time.time()
        callback = None
        with self._cond:
            if isinstance(message, MotorInfo):
                self._motor_parts.extend(message.motors)
                if message.more_follows:
                    return
                entries, self._motor_parts = self._motor_parts, []
                self._apply_motor_info(entries, now)
                self._completed(MessageId.MOTOR_INFO, MotorInfo(entries))
                callback = self.on_motor_update
            elif isinstance(message, PlaybackStatus):
                self._apply_playback(message, now)
                self._completed(-MessageId.NOTIFICATION, message)
                callback = self.on_playback and (lambda: self.on_playback(message))
            elif isinstance(message, MotorPosition):
                motor = self.motors.get(message.motor_address)
                if motor is not None and math.isfinite(message.position):
                    motor.position, motor.velocity, motor.stamp = message.position, 0.0, now
                self._completed(-1000 - message.motor_address, message)
                callback = self.on_motor_update
            elif isinstance(message, MotorCalibrated):
                motor = self.motors.get(message.motor_address)
                if motor is not None:
                    motor.begin_position = message.begin_position
                    motor.end_position = message.end_position
                    if message.end_position == 0.0:
                        motor.position = 0.0
                    else:
                        motor.position = message.end_position
                self._completed(-2000 - message.motor_address, message)
            elif isinstance(message, MotorStatus):
                for entry in message.motors:
                    motor = self.motors.setdefault(entry.address, MotorState(entry.address))
                    motor.online = entry.online
                    motor.is_fiz = entry.motor_type == 1
                    motor.max_setup_speed = entry.max_setup_speed
                    motor.max_move_speed = entry.max_move_speed
                    motor.max_acceleration = entry.max_acceleration
                    LOG.warning('motor %d is now %s', entry.address,
                                'online' if entry.online else 'OFFLINE')
                callback = self.on_motor_update
            elif isinstance(message, ErrorStatus):
                event = ErrorEvent(message.error_code, message.motor_address,
                                   describe_error(message.error_code), now)
                self.errors.append(event)
                self.error_total += 1
                motor = self.motors.get(message.motor_address)
                if motor is not None:
                    motor.last_error = message.error_code
                self._completed(-MessageId.NOTIFICATION - 3, message)
                LOG.warning('device error %d (%s), motor %d', event.code, event.description,
                            event.motor_address)
                callback = self.on_error and (lambda: self.on_error(event))
            elif isinstance(message, AuxInputStatus):
                self.aux_inputs = message.status
                status = message.status
                callback = self.on_aux_inputs and (lambda: self.on_aux_inputs(status))
            elif isinstance(message, UnsupportedMessage):
                self.unsupported_replies += 1
                LOG.warning('device did not support a message: %s', message.offending.hex())
                if len(message.offending) >= HEADER_SIZE:  # names the request it refuses
                    refused = unpack_header(message.offending).message_id
                    self._refused[refused] = self._refused.get(refused, 0) + 1
                    self._cond.notify_all()
            elif isinstance(message, UnknownMessage):
                LOG.debug('ignoring unknown message id %#x', message.message_id)
            else:   # responses: DeviceInfo, DeviceGuid, NetworkInfo, TrajectoryData, ...
                self._completed(message.MESSAGE_ID, message)
        if callback:
            callback()

    def _apply_motor_info(self, entries: list, now: float) -> None:
        seen = set()
        for entry in entries:
            seen.add(entry.address)
            values = (entry.position, entry.begin_position, entry.end_position,
                      entry.max_setup_speed, entry.max_move_speed, entry.max_acceleration)
            if not all(math.isfinite(v) for v in values):
                LOG.warning('ignoring MotorInfo for motor %d with non-finite values',
                            entry.address)
                continue
            motor = self.motors.setdefault(entry.address, MotorState(entry.address))
            if motor.stamp and now > motor.stamp:
                motor.velocity = (entry.position - motor.position) / (now - motor.stamp)
            motor.position = entry.position
            motor.begin_position = entry.begin_position
            motor.end_position = entry.end_position
            motor.max_setup_speed = entry.max_setup_speed
            motor.max_move_speed = entry.max_move_speed
            motor.max_acceleration = entry.max_acceleration
            motor.is_fiz = entry.is_fiz
            motor.online = True
            motor.stamp = now
        for address, motor in self.motors.items():
            if address not in seen:
                motor.online = False   # MotorInfo lists the connected motors only

    def _apply_playback(self, note: PlaybackStatus, now: float) -> None:
        pb = self.playback
        pb.status = note.status
        pb.elapsed = note.elapsed_time
        photos = note.photo_count
        pb.photo_count = round(photos) if math.isfinite(photos) and photos >= 0 else 0
        pb.positions = dict(note.positions)
        pb.history.append(note.status)
        if note.status == PlaybackState.SETUP_COMPLETED:
            pb.set_up = True
        if note.status == PlaybackState.FULL_STOP:
            pb.loaded = pb.set_up = False    # the move must be sent again
        for address, position in note.positions.items():
            motor = self.motors.get(address)
            if motor is not None and math.isfinite(position):
                motor.position, motor.stamp = position, now

    # ------------------------------------------------------------------- queries
    def refresh_motors(self) -> dict[int, MotorState]:
        self.request(GetMotorInfo())
        return self.motors

    def motor(self, address: int) -> MotorState:
        motor = self.motors.get(address)
        if motor is None:
            known = ', '.join(str(a) for a in sorted(self.motors)) or 'none'
            raise CommandRejected(f'motor {address} is not connected (connected: {known})')
        if not motor.online:
            raise CommandRejected(f'motor {address} is offline')
        return motor

    def wait_for(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Wait until predicate() (evaluated under the state lock) holds."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while not predicate():
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._cond.wait(min(remaining, 0.1))
        return True

    def _errors_since(self, marker: int) -> list[ErrorEvent]:
        """ErrorStatus events received after `marker` (a previous error_total)."""
        with self._lock:
            count = min(self.error_total - marker, len(self.errors))
            return list(self.errors)[len(self.errors) - count:] if count > 0 else []

    def _checked(self, action: Message, what: str) -> None:
        """Send an action followed by a barrier; raise if the device reported an error."""
        marker = self.error_total
        self.send(action)
        self.barrier()
        errors = self._errors_since(marker)
        if errors:
            first = errors[0]
            raise CommandRejected(f'{what}: device reported error {first.code} '
                                  f'({first.description}, motor {first.motor_address})')

    # ------------------------------------------------------------------ motion
    def _check_speed(self, motor: MotorState, speed: float, acceleration: float) -> None:
        if not math.isfinite(speed) or speed < 0:
            raise CommandRejected(f'speed must be a finite value >= 0, got {speed}')
        if speed > motor.max_setup_speed:
            raise CommandRejected(f'motor {motor.address}: speed {speed:.3f} rot/s exceeds '
                                  f'MaxMaxSetupSpeed {motor.max_setup_speed:.3f}')
        if not math.isfinite(acceleration) or acceleration < 0:
            raise CommandRejected(f'acceleration must be finite and >= 0, got {acceleration}')
        if acceleration > motor.max_acceleration:
            raise CommandRejected(f'motor {motor.address}: acceleration {acceleration:.3f} '
                                  f'rot/s^2 exceeds MaxMaxAcceleration '
                                  f'{motor.max_acceleration:.3f}')

    @property
    def playback_running(self) -> bool:
        """True while the device executes a move (it then owns the motors)."""
        return self.playback.status in PLAYBACK_RUNNING_STATES

    def check_move(self, address: int, position: float, speed: float,
                   acceleration: float | None = None) -> SetPositionSpeedAcceleration:
        """The message for an absolute move, or CommandRejected (nothing is sent)."""
        motor = self.motor(address)
        accel = motor.max_acceleration if acceleration is None else acceleration
        self._check_speed(motor, speed, accel)
        lo, hi = motor.travel()
        if not math.isfinite(position) or not lo - 1e-9 <= position <= hi + 1e-9:
            state = 'calibrated range' if motor.calibrated else 'uncalibrated travel'
            raise CommandRejected(f'motor {address}: position {position:.4f} rot is outside '
                                  f'the {state} [{lo:.4f}, {hi:.4f}]')
        return SetPositionSpeedAcceleration(address, min(max(position, lo), hi), speed, accel)

    def move_to(self, address: int, position: float, speed: float,
                acceleration: float | None = None) -> None:
        """Absolute move in rotations (calibrated: within 0..EndPosition)."""
        self.send(self.check_move(address, position, speed, acceleration))

    def bump(self, address: int, delta: float, speed: float,
             acceleration: float | None = None) -> None:
        """Relative move (BumpPositionSpeedAcceleration), checked against the range."""
        motor = self.motor(address)
        accel = motor.max_acceleration if acceleration is None else acceleration
        self._check_speed(motor, speed, accel)
        lo, hi = motor.travel()
        target = motor.position + delta
        if not math.isfinite(delta) or not lo <= target <= hi:
            raise CommandRejected(f'motor {address}: bump by {delta:.4f} rot would end at '
                                  f'{target:.4f}, outside [{lo:.4f}, {hi:.4f}]')
        self.send(BumpPositionSpeedAcceleration(address, delta, speed, accel))

    def jog(self, address: int, velocity: float, acceleration: float | None = None) -> None:
        """Move at `velocity` rot/s toward the end of travel (0 stops)."""
        motor = self.motor(address)
        if velocity == 0:
            self.stop_motor(address)
            return
        accel = motor.max_acceleration if acceleration is None else acceleration
        self._check_speed(motor, abs(velocity), accel)
        lo, hi = motor.travel()
        self.send(SetPositionSpeedAcceleration(address, hi if velocity > 0 else lo,
                                               abs(velocity), accel))

    def stop_motor(self, address: int) -> None:
        motor = self.motor(address)
        self.send(SetPositionSpeedAcceleration(address, motor.position, 0.0,
                                               motor.max_acceleration))

    def stop_all(self) -> None:
        """StopPlayback (stops every motor immediately) and speed 0 for each motor."""
        self.send(StopPlayback())
        for address, motor in list(self.motors.items()):
            if motor.online:
                self.send(SetPositionSpeedAcceleration(address, motor.position, 0.0,
                                                       motor.max_acceleration))

    def take_picture(self, exposure: float = 0.0) -> None:
        if not math.isfinite(exposure) or exposure < 0:
            raise CommandRejected(f'exposure must be >= 0 s, got {exposure}')
        self._checked(TakePicture(ALL_MOTORS, exposure), 'TakePicture')

    # ------------------------------------------------------------ device settings
    def led_status(self) -> tuple[int, int]:
        """(Get)LEDStatus: (master, slave), each a LedState (0 off, 1 on, 2/3 blink)."""
        reply = self.request(GetLedStatus())
        assert isinstance(reply, LedStatus)
        return reply.master_status, reply.slave_status

    def set_led_status(self, master: int, slave: int) -> tuple[int, int]:
        """(Set)LEDStatus, then read the LEDs back (a Set has no reply)."""
        allowed = [int(s) for s in LedState]
        for name, value in (('master', master), ('slave', slave)):
            if value not in allowed:
                raise CommandRejected(f'{name} LED status {value!r} is not one of {allowed} '
                                      '(0 off, 1 on, 2 slow blink, 3 fast blink)')
        self.send(LedStatus(int(master), int(slave)))
        return self.led_status()

    def software_id(self) -> int:
        """(Get)SoftwareID: the platform id of the last client that used the device."""
        reply = self.request(GetSoftwareId())
        assert isinstance(reply, SoftwareId)
        return reply.device_type

    def set_software_id(self, platform: int) -> int:
        """(Set)SoftwareID, read back; the caller decides whether writing it is allowed."""
        if isinstance(platform, bool) or not isinstance(platform, int) \
                or not 0 <= platform <= 0xFF:
            raise CommandRejected(f'SoftwareID must be an integer 0..255, got {platform!r}')
        self.send(SoftwareId(platform))
        return self.software_id()

    # ------------------------------------------------------------- calibration
    def mark_begin(self, address: int) -> None:
        self.motor(address)
        self._checked(MarkBeginPosition(address), f'MarkBeginPosition motor {address}')

    def _await_calibrated(self, address: int, seq0: int, timeout: float, what: str) -> None:
        key = -2000 - address
        if not self.wait_for(lambda: self._seq.get(key, 0) > seq0, timeout):
            errors = [e for e in self.errors if e.motor_address == address]
            reason = f' (device error {errors[-1].code}: {errors[-1].description})' \
                if errors else ''
            raise DeviceTimeout(f'{what}: no MotorCalibrated notification for motor '
                                f'{address}{reason}')

    def mark_end(self, address: int, timeout: float | None = None) -> tuple[float, float]:
        """MarkEndPosition; returns (begin, end) from the MotorCalibrated notification."""
        self.motor(address)
        with self._lock:
            seq0 = self._seq.get(-2000 - address, 0)
        marker = self.error_total
        self.send(MarkEndPosition(address))
        self.barrier()
        failed = [e for e in self._errors_since(marker) if e.code == ErrorCode.CALIBRATION]
        if failed:
            raise CommandRejected(f'motor {address}: calibration failed (error 14: the end '
                                  'mark must differ from the begin mark); the axis was reset')
        self._await_calibrated(address, seq0, timeout or self.reply_timeout, 'MarkEndPosition')
        motor = self.motors[address]
        return motor.begin_position, motor.end_position

    def reset_axis(self, address: int, timeout: float | None = None) -> None:
        """Clear calibration (address 0: every axis, no notification expected)."""
        if address != ALL_MOTORS:
            self.motor(address)
        with self._lock:
            seq0 = self._seq.get(-2000 - address, 0)
        self.send(ResetAxis(address))
        if address == ALL_MOTORS:
            self.barrier()
            self.refresh_motors()
            return
        self._await_calibrated(address, seq0, timeout or self.reply_timeout, 'ResetAxis')

    # ---------------------------------------------------------------- playback
    def load_trajectory(self, trajectory: Trajectory) -> None:
        """Validate against the motors' calibration and maxima, send, and confirm."""
        self.refresh_motors()
        limits = {a: m.limits() for a, m in self.motors.items() if m.online}
        try:
            validate(trajectory, limits)
        except ProtocolError as exc:
            raise CommandRejected(f'trajectory refused before sending: {exc}') from exc
        with self._lock:
            self.playback.loaded = False
            self.playback.set_up = False
            self.playback.history = []
        marker = self.error_total
        self.send(trajectory.to_message())
        echo = self.request(GetTrajectoryData())   # barrier + confirmation
        errors = self._errors_since(marker)
        if errors:
            raise CommandRejected(f'device rejected the trajectory: error {errors[0].code} '
                                  f'({errors[0].description})')
        expected = len(trajectory.to_message().blocks)
        if not isinstance(echo, TrajectoryData) or len(echo.blocks) != expected:
            raise CommandRejected('device did not store the trajectory (GetTrajectoryData '
                                  'returned a different move)')
        with self._lock:
            self.playback.loaded = True

    def setup_playback(self, delay_return: bool = False) -> None:
        if not self.playback.loaded:
            raise CommandRejected('no trajectory loaded (a FullStop consumes the move; load '
                                  'it again)')
        self._checked(SetupPlayback(0, 0.0, delay_return), 'SetupPlayback')

    def start_playback(self) -> None:
        if not self.playback.loaded:
            raise CommandRejected('no trajectory loaded (a FullStop consumes the move; load '
                                  'it again)')
        self._checked(StartPlayback(0, 0.0), 'StartPlayback')

    def stop_playback(self) -> None:
        self.send(StopPlayback())

    def rapid_to_first_key_frame(self) -> None:
        if not self.playback.loaded:
            raise CommandRejected('RapidToFirstKeyFrame needs a loaded trajectory')
        self._checked(RapidToFirstKeyFrame(), 'RapidToFirstKeyFrame')

    def wait_playback(self, status: int, timeout: float) -> bool:
        """Wait until a PlaybackStatus `status` has been seen since the last load."""
        return self.wait_for(lambda: status in self.playback.history, timeout)
