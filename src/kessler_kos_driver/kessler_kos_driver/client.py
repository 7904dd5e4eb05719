"""Kessler kOS device session over TCP or USB HID (no ROS).

Responsibilities: discovery (listen for NetworkInfo datagrams), the initialisation sequence
(DeviceInfo, UserPassword, MotorInfo, DeviceGUID), request/response matching, notification
handling (motor, playback, error state, aux inputs), the 10 s keep-alive, periodic state
polling (both in the tick of the session's one reader thread, ``kos-reader``: the link is
a :class:`gimbal_driver_common.session.Session` and the client its protocol) and the
commands in the device's own units (rotations); the adapter checks limits, in SI, before it
calls them. Reconnecting is not the client's job: the controller's supervisor
(gimbal_driver_common.controller) calls :meth:`KosClient.connect` again after a loss,
which the client reports through `connected` and `last_error_text`. Over USB
(`usb=UsbTarget(...)`) the link is a :class:`~.usb_link.HidStream` (report framing and the
4 s USB keep-alive) and no password message is sent: the document's USB notes say
UserPassword and DevicePassword are "not required or supported".

The client's parts, each handed what it uses: the state the session keeps
(:attr:`KosClient.state`, :class:`~.client_state.KosState`), the notification handling
(:attr:`KosClient.notifications`, :class:`~.client_notifications.KosNotifications`, which
writes that state and owns the adapter's ``on_*`` callbacks) and the commands
(:attr:`KosClient.commands`, :class:`~.client_commands.KosCommands`, handed the client's
messaging and the state).

Design notes:
- Set messages and actions have no reply. Where the caller needs to know the outcome the client
  follows them with a Get as a *barrier*: the device handles messages in order, so any
  ErrorStatus caused by the action arrives before the barrier's response.
- Responses are matched by MessageID (a request takes the first one after it was sent), so
  unsolicited responses (the device sends NetworkInfo over TCP while connected, polls
  overlap) are harmless.
- The password is never logged or put in exception text; DeviceInfo carries the device password
  and its repr hides it.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable

from gimbal_driver_common import errors
from gimbal_driver_common.errors import LinkError
from gimbal_driver_common.session import Protocol, Session, StreamLink
from gimbal_driver_common.transport import ByteStream, TcpStream, TransportError
from gimbal_driver_common.unanswered import ConnectReads

from .client_commands import KosCommands
from .client_notifications import KosNotifications
from .client_state import KosState
from .client_types import (
    CommandRejected,  # noqa: F401 - re-exported: the client's callers catch it from here
    DeviceTimeout,
    ErrorEvent,
    KosError,
    MessageUnsupported,
    MotorState,
    NotConnected,
    PasswordRejected,
    PlaybackInfo,
    discover,
)
from .protocol import (
    DEFAULT_TCP_PORT,
    HEADER_SIZE,
    KEEPALIVE_PERIOD_S,
    REPORT_SIZE,
    USB_KEEPALIVE_PERIOD_S,
    AuxInputStatus,
    DeviceGuid,
    DeviceInfo,
    ErrorCode,
    ErrorStatus,
    FrameParser,
    GetDeviceGuid,
    GetDeviceInfo,
    GetMotorInfo,
    GetNetworkInfo,
    Message,
    MotorCalibrated,
    MotorInfo,
    MotorPosition,
    MotorStatus,
    PlaybackStatus,
    ProtocolError,
    UnknownMessage,
    UnsupportedMessage,
    UserPassword,
    decode,
    unpack_header,
)
from .protocol.messages import MotorInfoEntry
from .usb_link import HidDevice, HidStream, UsbTarget

LOG = logging.getLogger('kessler_kos_driver.client')


#: messages that are notifications, never the answer to a Get
NOTIFICATIONS = (PlaybackStatus, MotorPosition, MotorCalibrated, MotorStatus, ErrorStatus,
                 AuxInputStatus, UnsupportedMessage, UnknownMessage)


class KosClient(Protocol):
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
            # A kOS device that leaves Nagle's algorithm on would hold a reply behind the
            # delayed ACK of its previous one; TcpStream acknowledges every read at once
            # (TCP_QUICKACK), so polls and notifications are not held for 40 ms.
            self._stream_factory = stream_factory or (
                lambda h, p: TcpStream(h, p, connect_timeout))
        self._stream: ByteStream | None = None
        self._session: Session | None = None
        self._parser = FrameParser()
        self._connected_host = ''
        self.state = KosState()
        self._lock = self.state.lock
        self.notifications = KosNotifications(self.state)
        self.commands = KosCommands(self, self.state)
        self._motor_parts: list[MotorInfoEntry] = []
        self._last_tx = 0.0
        self._last_rx = 0.0
        self._unanswered_since: float | None = None   # first send after the last receive
        self.silence_timeout = max(2.0 * reply_timeout, 1.0)
        self._next_poll = 0.0
        self.connected = False
        self.device_info: DeviceInfo | None = None
        self.guid = ''
        #: best-effort connect requests the device left unanswered (the GUID)
        self.unanswered = ConnectReads(LOG.warning)
        self.malformed_frames = 0
        self.last_error_text = ''      # why the link was lost (for the supervisor's reason)

    # ----------------------------------------------- the state, read-only (see state)
    @property
    def motors(self) -> dict[int, MotorState]:
        return self.state.motors

    @property
    def playback(self) -> PlaybackInfo:
        return self.state.playback

    @property
    def playback_running(self) -> bool:
        return self.state.playback_running

    @property
    def errors(self) -> deque[ErrorEvent]:
        return self.state.errors

    @property
    def error_total(self) -> int:
        return self.state.error_total

    @property
    def aux_inputs(self) -> int:
        return self.state.aux_inputs

    @property
    def unsupported_replies(self) -> int:
        return self.state.unsupported_replies

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
        self.state.reset_counts()
        with self._lock:
            self._stream = stream
            self._motor_parts = []
            self._unanswered_since = None
        self._parser = FrameParser()
        self._session = Session(StreamLink(stream), self, 'kos', read_timeout=0.02,
                                link_error=NotConnected).start()
        try:
            self._initialise()
        except Exception:
            self.close()
            raise
        self._next_poll = time.monotonic()
        self.connected = True
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
            self.state.aux_inputs = info.aux_input_status
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
            if any(e.code == ErrorCode.LOCKED_OUT
                   for e in self.state.errors_since(errors_before)):
                raise PasswordRejected('the device rejected the password (ErrorStatus 15, '
                                       'locked out)') from exc
            raise
        self._finish_initialisation(info)

    def _finish_initialisation(self, info: DeviceInfo) -> None:
        """The GUID is best effort (an identity detail): DeviceInfo, the password and the
        motors are what the node cannot work without, and their failures name them."""
        self.unanswered.clear()
        guid = self.unanswered.read('GetDeviceGuid', lambda: self.request(GetDeviceGuid()),
                                    (DeviceTimeout, MessageUnsupported))
        assert guid is None or isinstance(guid, DeviceGuid)
        self.guid = '' if guid is None else guid.text
        with self._lock:
            self.state.playback.status = info.playback_status

    def close(self) -> None:
        """Close the link and end the session's reader (safe to call repeatedly)."""
        self.connected = False
        session, self._session = self._session, None
        if session is not None:
            session.close()
        with self._lock:
            self._stream = None
        self.state.wake()

    # ------------------------------------------------------------------- messaging
    def send(self, message: Message) -> None:
        """Encode (checks ranges) and send one message."""
        data = message.encode()
        session = self._session
        if session is None or not session.alive:
            raise NotConnected(f'not connected to {self.description}')
        try:
            session.write(data)
        except errors.LinkError as exc:
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
        what = type(message).__name__

        def answers(reply: Message) -> bool | KosError:
            if isinstance(reply, UnsupportedMessage):
                if len(reply.offending) >= HEADER_SIZE \
                        and unpack_header(reply.offending).message_id == message_id:
                    return MessageUnsupported(f'{self.description} answered {what} with '
                                              'UnsupportedMessage: the device does not '
                                              'support it')
                return False
            return not isinstance(reply, NOTIFICATIONS) and message_id == reply.MESSAGE_ID

        session = self._session
        if session is None:
            raise NotConnected(f'not connected to {self.description}')
        try:
            with session.expect(answers) as pending:
                self.send(message)
                return pending.next(timeout)
        except errors.LinkError as exc:
            raise NotConnected(f'link to {self.description} lost while waiting for the '
                               f'reply to {what}') from exc
        except errors.DeviceTimeout as exc:
            raise DeviceTimeout(f'no reply to {what} from {self.description} '
                                f'within {timeout:.1f} s') from exc

    def barrier(self) -> None:
        """Wait until the device has handled everything sent so far."""
        self.request(GetNetworkInfo(False))

    # ------------------------------------------------------- session (reader thread)
    def connection_made(self, session: Session) -> None:
        session.on(Message, self.notifications.dispatch)

    def data_received(self, data: bytes) -> None:
        """Frames → messages (MotorInfo parts joined into one) → the session's dispatch."""
        self._last_rx = time.monotonic()
        self._unanswered_since = None
        parser, session = self._parser, self._session
        before = parser.discarded_bytes
        for frame in parser.feed(data):
            try:
                message = decode(frame)
            except ProtocolError as exc:
                self.malformed_frames += 1
                LOG.warning('ignoring malformed kOS frame: %s', exc)
                continue
            if isinstance(message, MotorInfo):
                self._motor_parts.extend(message.motors)
                if message.more_follows:
                    continue
                message, self._motor_parts = MotorInfo(self._motor_parts), []
            if session is not None:
                session.dispatch(message)
        if parser.discarded_bytes != before:
            self.malformed_frames += 1
            LOG.warning('skipped %d garbage bytes from %s while resynchronising',
                        parser.discarded_bytes - before, self.description)

    def connection_lost(self, error: LinkError | None) -> None:
        """The link is gone (``error``) or was closed: requests and the poll stop."""
        was_connected, self.connected = self.connected, False
        if error is not None and was_connected:
            self.last_error_text = f'link lost: {error}'
        self.state.wake()

    def tick(self, now: float) -> float | None:
        """State polling (GetMotorInfo), the keep-alive (GetNetworkInfo when idle) and the
        silent-device check (requests sent, nothing received for silence_timeout); the
        answer is when the next poll is due (the reader wakes for it exactly)."""
        if not self.connected:
            return None
        waiting = self._unanswered_since
        if waiting is not None and now - waiting > self.silence_timeout:
            raise NotConnected(f'device silent: no reply for {now - waiting:.1f} s')
        if self.poll_period > 0 and now >= self._next_poll:
            self._next_poll += self.poll_period
            if self._next_poll <= now:  # fell behind: do not burst to catch up
                self._next_poll = now + self.poll_period
            self.send(GetMotorInfo())
        elif self.keepalive_period > 0 and now - self._last_tx >= self.keepalive_period:
            self.send(GetNetworkInfo(False))
        return self._next_poll if self.poll_period > 0 else None

    # ------------------------------------------------------------------- queries
    def refresh_motors(self) -> dict[int, MotorState]:
        self.request(GetMotorInfo())
        return self.motors

    def motor(self, address: int) -> MotorState:
        """A connected, online motor (:meth:`KosState.motor`)."""
        return self.state.motor(address)

    def wait_for(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Wait until predicate() (evaluated under the state lock) holds."""
        return self.state.wait_for(predicate, timeout)
