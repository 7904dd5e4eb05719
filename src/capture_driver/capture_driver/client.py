"""Capture pedestal session: handshake, request/reply, keep-alive, resync and reconnect.

One request is in flight at a time (a lock serialises callers from any thread). A request
writes one packet and reads until its reply: a data packet with the same opcode and axis
for getters, a single ACK byte for everything else, or a NACK byte, which raises
:class:`DeviceNack` carrying the spec's meaning and advice. A reply of the other kind (an
ACK to a getter, data to a setter) raises :class:`WrongReply`: the device answered, so it
is a protocol error of that request, never silence; only no answer at all is a
:class:`DeviceTimeout`, and only timeouts in a row close the link ("device silent").
Garbage and corrupted or truncated packets are skipped by
:class:`~.protocol.StreamDecoder`; if a started packet stalls for ``resync_gap`` the
decoder gives it up and rescans, so a lost byte costs at most one request.

Requests the host makes on its own (identity, probes, the status registers, the sensor
polls: :meth:`CaptureClient.optional` and :meth:`CaptureClient.poll`) stop being sent once
the device answered one with 0xA6 or with the wrong kind of reply (:attr:`unsupported`);
so does the one advisory step of a move, MOT_SetTum (4.2.14, 7.1 "as needed").

Handshake (section 6.1): over TCP the controller sends a COM_Connect packet as soon as the
connection opens; the client answers with a COM_Connect packet carrying the opcode the
controller used (so a wrong reconstruction of that opcode cannot break the handshake) and
waits for the ACK. On a serial line there is no greeting; the client sends COM_Connect.

Keep-alive (4.6.5): with ``keepalive_period`` > 0 the client configures the controller's
supervision (COM_setKeepAliveTimeout/Count, COM_StartKeepAlive) so a dead host makes the
pedestal stop, and a background thread (:meth:`CaptureClient.start`) sends COM_IsKeepAliveOn
whenever the link has been idle for ``keepalive_period``.

A lost link raises :class:`NotConnected` and stays closed: reopening it is the job of the
one connection supervisor, :class:`gimbal_driver_common.controller.GimbalController`, which
calls :meth:`CaptureClient.connect` through the device adapter (``device.py``). The errors
subclass the shared hierarchy in :mod:`gimbal_driver_common.errors`.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from gimbal_driver_common import errors
from gimbal_driver_common.fair_lock import FairRLock
from gimbal_driver_common.transport import ByteStream, TransportError

from .protocol import (
    REPLY_INFO,
    Frame,
    GeoPoint,
    PresetRecord,
    ProtocolError,
    ReplyByte,
    ReplyCode,
    StreamDecoder,
    command,
    ddmm_to_degrees,
)
from .protocol.registers import CSR_ERROR_STRINGS, CSR_PROTOCOL_ERROR, REGISTERS

LOG = logging.getLogger('capture_driver.client')

GPS_FIX_COMMANDS = ('GPS_PositionReady', 'GPS_GetLatitude', 'GPS_GetLongitude')

#: batched reads in a row that came back incomplete before :meth:`CaptureClient.read_many`
#: falls back to one request at a time for the connection
BATCH_FAILURES = 3

SCAN_COMMANDS = {
    'zigzag': 'SCN_StartScanZigZag',
    'snake': 'SCN_StartScanSnake',
    'square': 'SCN_StartScanSquare',
}


class CaptureError(errors.GimbalError):
    """Base of the client's errors; the message is meant for a person."""


class NotConnected(CaptureError, errors.LinkError):
    """No link to the controller (not opened yet, or lost: the supervisor reconnects)."""


class DeviceTimeout(CaptureError, errors.DeviceTimeout):
    """The controller did not answer in time."""


class WrongReply(CaptureError, errors.DeviceRefused):
    """The controller answered, but with the other kind of reply: an ACK byte where the
    request takes a data packet, a data packet where it takes an ACK, or data that does not
    decode. A protocol error of that request (the link stays up), never silence."""

    def __init__(self, request: str, answer: str, expected: str) -> None:
        super().__init__(f'{request} answered {answer}, expected {expected}')
        self.request = request
        self.answer = answer
        self.expected = expected


class NotSupported(CaptureError, errors.Unsupported):
    """A request the host makes on its own that the device answered with 0xA6 or the wrong
    kind of reply; it is not sent again on this connection (:attr:`CaptureClient.unsupported`)."""

    def __init__(self, name: str, answer: str) -> None:
        super().__init__(f'{name}: the device does not support it ({answer}); '
                         'not asked again on this connection')
        self.name = name
        self.answer = answer


class DeviceNack(CaptureError, errors.DeviceRefused):
    """The controller answered with a NACK byte; the message carries its meaning."""

    def __init__(self, request: str, code: ReplyCode, detail: str = '') -> None:
        info = REPLY_INFO[code]
        message = f'{request}: NACK 0x{int(code):02X} {info.title} ({info.meaning})'
        if detail:
            message += f'; device says: {detail}'
        if info.advice:
            message += f'; {info.advice}'
        super().__init__(message)
        self.code = code
        self.request = request
        self.detail = detail


#: what a request can fail with while the link stays up: a NACK, a reply of the wrong kind,
#: no reply (DeviceTimeout). NotConnected (the link is gone) is not among them.
REQUEST_ERRORS: tuple[type[CaptureError], ...] = (DeviceNack, WrongReply, DeviceTimeout)

#: motion set-up steps the protocol calls advisory (4.2.14 "it is advisable to send this
#: command before each command session", 7.1 "MOT_SetTum (as needed)"): a controller that
#: does not know one (0xA6 while the rest of the set-up is accepted) is driven without it
ADVISORY_STEPS = frozenset({'MOT_SetTum'})

IDENTITY_GETTERS = (('serial_number', 'COM_GetSn'), ('firmware', 'COM_GetFw'),
                    ('hardware', 'COM_GetHw'), ('part_number', 'COM_GetPn'))


@dataclass
class PostedMoves:
    """A stream move written by :meth:`CaptureClient.post_moves` whose ACKs nobody has read
    yet: per axis ``(position_deg, speed_deg_s, acceleration)`` and the frames, in order."""

    moves: dict[int, tuple[float, float, float]]
    frames: list[tuple[str, Frame]]
    settled: bool = False
    #: the client's count of setters sent when this was written (see finish_posted)
    setters_at_post: int = 0
    #: the device's refusal, or the link lost, found when the ACKs were read
    error: CaptureError | None = None
    #: some ACK never came, or a NACK says the packet was not executed (0xF6): the moves
    #: are sent again, one request at a time (the same target twice is harmless)
    resend: bool = False


@dataclass
class Identity:
    serial_number: str = ''
    firmware: str = ''
    hardware: str = ''
    part_number: str = ''
    #: getter -> how it failed (the ones that gave no value)
    problems: dict[str, str] = field(default_factory=dict)


class CaptureClient:
    """Thread-safe session with one Capture controller over any :class:`ByteStream`."""

    def __init__(
        self,
        stream_factory: Callable[[], ByteStream],
        group: int = 0,
        timeout: float = 0.5,
        greeting_timeout: float = 0.5,
        expect_greeting: bool = True,
        keepalive_period: float = 0.0,
        keepalive_count: int = 3,
        resync_gap: float = 0.05,
        max_timeouts: int = 3,
        batch_reads: bool = True,
    ) -> None:
        self._stream_factory = stream_factory
        self.group = group
        self.timeout = timeout
        self.greeting_timeout = greeting_timeout
        self.expect_greeting = expect_greeting
        self.keepalive_period = keepalive_period
        self.keepalive_count = keepalive_count
        self.resync_gap = resync_gap
        self.max_timeouts = max_timeouts
        # fair: a command stream must not starve the joint poll (gimbal_driver_common.fair_lock)
        self._lock = FairRLock()
        self._stream: ByteStream | None = None
        self._decoder = StreamDecoder()
        self._connected = False
        self._connect_opcode = command('COM_Connect').opcode
        self._last_activity = 0.0
        self._consecutive_timeouts = 0
        # axis -> (mode, acceleration, speed, TUM armed) this client's last motion set-up
        # left on the device (armed: a TUM was sent for the next absolute move, see
        # move_absolute); forgotten on connect and on any other command that changes something
        self._setups: dict[int, tuple[str, float | None, float | None, bool]] = {}
        self._in_setup = False
        #: input may hold a reply to an earlier request (see :meth:`_drain`)
        self._stale_possible = True
        #: getters of :meth:`read_many` go out in one write (False: one at a time)
        self.batch_reads = batch_reads
        self.batching = batch_reads
        self._batch_failures = 0
        #: a stream move written without waiting for its ACKs (see :meth:`post_moves`)
        self._posted: PostedMoves | None = None
        #: setters sent on this client (a posted move is not re-sent after another one)
        self._setters_sent = 0
        self._worker: threading.Thread | None = None
        self._stop = threading.Event()
        self.last_error = 'not connected'
        self.connects = 0
        self.stats = {'requests': 0, 'timeouts': 0, 'nacks': 0, 'wrong_replies': 0,
                      'stale': 0, 'incomplete_batches': 0, 'posted_moves': 0}
        # Commands the host sends on its own that the device answered with 0xA6 or with the
        # wrong kind of reply (name -> its answer); never sent again on this connection.
        self.unsupported: dict[str, str] = {}
        #: replies of the wrong kind per command (name -> (count, the last answer))
        self.wrong_replies: dict[str, tuple[int, str]] = {}
        self._keepalive_on = False

    # ---------------------------------------------------------------- link
    @property
    def connected(self) -> bool:
        return self._connected

    @property
    def description(self) -> str:
        stream = self._stream
        return stream.description if stream is not None else ''

    @property
    def garbage_bytes(self) -> int:
        return self._decoder.garbage_bytes

    def connect(self) -> None:
        """Open the link and run the handshake; raises :class:`CaptureError` on failure."""
        with self._lock:
            self._close_locked()
            stream = self._stream_factory()
            try:
                stream.open()
            except TransportError as exc:
                self.last_error = str(exc)
                raise NotConnected(str(exc)) from exc
            self._stream = stream
            self._decoder.reset()
            self._stale_possible = True
            self.batching, self._batch_failures = self.batch_reads, 0
            self.unsupported = {}  # a new connection may be a different controller
            self.wrong_replies = {}
            self._keepalive_on = False
            try:
                self._handshake()
                self._connected = True
                self._consecutive_timeouts = 0
                if self.keepalive_period > 0:
                    self._configure_keepalive()
            except (CaptureError, TransportError) as exc:
                self.last_error = f'handshake with {stream.description} failed: {exc}'
                self._close_locked()
                raise NotConnected(self.last_error) from exc
            self.connects += 1
            self.last_error = ''
        LOG.info('connected to %s', self.description)

    def _handshake(self) -> None:
        if self.expect_greeting:
            greeting = self._wait_greeting(self.greeting_timeout)
            if greeting is not None:
                self._connect_opcode = greeting.opcode
        frame = Frame(self.group, 0, self._connect_opcode)
        self._transact('COM_Connect', frame, expect_data=False, timeout=self.timeout)

    def _wait_greeting(self, timeout: float) -> Frame | None:
        assert self._stream is not None
        deadline = time.monotonic() + timeout
        while (remaining := deadline - time.monotonic()) > 0:
            for item in self._decoder.feed(self._stream.read(256, remaining)):
                if isinstance(item, Frame) and not item.data and 0x0700 <= item.opcode <= 0x07FF:
                    return item
        return None

    def _configure_keepalive(self) -> None:
        timeout_ms = max(int(self.keepalive_period * 1000), 100)
        try:
            self._request_locked('COM_setKeepAliveTimeout', None, min(timeout_ms, 0xFFFF))
            self._request_locked('COM_setKeepAliveCount', None, self.keepalive_count)
            self._request_locked('COM_StartKeepAlive', None, 1)
        except (DeviceNack, WrongReply) as exc:  # firmware before 2.13.6 has no keep-alive
            LOG.warning('controller keep-alive not available: %s', exc)
            return
        self._keepalive_on = True

    def close(self, send_disconnect: bool = False) -> None:
        """Close the link cleanly.

        A configured controller keep-alive is switched off first (a clean close is not a
        dead host: the axes keep their power and position); with ``send_disconnect`` the
        controller also gets COM_Disconnect, which powers the motors off (4.6.3).
        """
        with self._lock:
            if self._connected and self._keepalive_on:
                with contextlib.suppress(CaptureError, TransportError, ProtocolError):
                    self._request_locked('COM_StartKeepAlive', None, 0, timeout=0.2)
            if send_disconnect and self._connected:
                with contextlib.suppress(CaptureError, TransportError, ProtocolError):
                    self._request_locked('COM_Disconnect', None, None, timeout=0.2)
            self._close_locked()

    def _close_locked(self) -> None:
        self._connected = False
        self._setups.clear()
        posted = self._posted
        if posted is not None and not posted.settled:
            posted.settled = True
            posted.error = NotConnected(f'stream move: link closed before its ACKs came '
                                        f'({self.last_error})')
        stream, self._stream = self._stream, None
        if stream is not None:
            stream.close()

    def _link_lost(self, why: str) -> None:
        self.last_error = why
        if self._connected:
            LOG.warning('link lost: %s', why)
        self._close_locked()

    def start(self) -> None:
        """Start the keep-alive thread (needed only with ``keepalive_period`` > 0)."""
        if self._worker is not None and self._worker.is_alive():
            return
        self._stop.clear()
        self._worker = threading.Thread(target=self._run, name='capture-keepalive', daemon=True)
        self._worker.start()

    def stop(self, send_disconnect: bool = False) -> None:
        self._stop.set()
        if self._worker is not None and self._worker is not threading.current_thread():
            self._worker.join(timeout=2.0)
        self._worker = None
        self.close(send_disconnect)

    def _run(self) -> None:
        tick = 0.05
        while not self._stop.wait(tick):
            if self._connected and self._keepalive_on and (
                time.monotonic() - self._last_activity >= self.keepalive_period
            ):
                with contextlib.suppress(CaptureError):
                    self.optional('COM_IsKeepAliveOn')

    # ------------------------------------------------------------- requests
    def request(self, name: str, axis: int | None = None, value: Any = None,
                timeout: float | None = None) -> Any:
        """Send one table command and return its decoded reply (None for ACK-only commands).

        Raises :class:`ProtocolError` for bad arguments (nothing is sent),
        :class:`DeviceNack`, :class:`WrongReply`, :class:`DeviceTimeout` or
        :class:`NotConnected`.
        """
        cmd = command(name)
        with self._lock:
            return self._request_locked(cmd.name, axis, value, timeout)

    def _request_locked(self, name: str, axis: int | None, value: Any,
                        timeout: float | None = None, group: int | None = None) -> Any:
        cmd = command(name)
        # validates before anything is sent
        frame = cmd.frame(axis, value, self.group if group is None else group)
        if self._stream is None:
            raise NotConnected(f'{name}: not connected ({self.last_error})')
        if not cmd.replies_with_data:
            self._setters_sent += 1
            if not self._in_setup:
                self._setups.clear()  # anything may have changed an axis' mode or profile
        for attempt in (1, 2):
            try:
                reply = self._transact(name, frame, cmd.replies_with_data,
                                       self.timeout if timeout is None else timeout)
                return self._decode(name, frame, reply) if cmd.replies_with_data else None
            except DeviceNack as exc:
                # 0xF6: the controller did not execute the packet, so resending is safe.
                if exc.code == ReplyCode.WRONG_CHECKSUM and attempt == 1:
                    continue
                raise
            except (DeviceTimeout, WrongReply):
                # A getter changes nothing, so it is retried once (a reply of the wrong kind
                # is named only when the device gives it twice: noise can look like an ACK
                # byte); a setter is not.
                if cmd.replies_with_data and attempt == 1:
                    continue
                raise
        raise DeviceTimeout(f'{name}: no reply')  # pragma: no cover

    def _decode(self, name: str, frame: Frame, reply: Frame) -> Any:
        """A getter's value; data that does not decode is a reply of the wrong kind."""
        try:
            return command(name).decode_reply(reply)
        except ProtocolError as exc:
            raise self._wrong_reply(name, frame, f'{len(reply.data)} data bytes ({exc})',
                                    'data') from None

    def read_many(self, reads: Sequence[tuple[str, int | None]],
                  optional: bool = False) -> list[Any]:
        """Several getters (``(name, axis)``) written at once, their replies matched by
        opcode and axis; returns the decoded values in order.

        ``optional``: reads the host makes on its own (the status registers), each as
        :meth:`poll`: None for a getter the device does not answer with data (it is not
        sent again), so the rest are read from what the device does report.

        A data reply names the opcode and axis it answers (section 3), so getters need not
        wait for each other: the joint poll (position and speed of each axis) costs one
        round trip instead of four, and holds the link for that long only. The protocol
        document shows one request at a time and says nothing of queuing, so this is our
        reading of it, with a way back: a batch that gets a NACK or misses a reply has
        the missing reads sent again one at a time (with :meth:`request`'s retry rules),
        and after ``BATCH_FAILURES`` such batches in a row the client reads one at a
        time for the rest of the connection (:attr:`batching` says which, in diagnostics).
        An ACK byte names neither opcode nor axis: in a batch it only says that one of the
        reads got no data, and that read is then named by asking it alone.
        """
        frames = []
        for name, axis in reads:
            cmd = command(name)
            if not cmd.replies_with_data:
                raise ProtocolError(f'{name} is not a getter: only getters are batched')
            frames.append((cmd, axis, cmd.frame(axis, None, self.group)))
        with self._lock:
            values: list[Any] = [None] * len(frames)
            asked = [i for i, (cmd, _, _) in enumerate(frames)
                     if not (optional and cmd.name in self.unsupported)]
            replies: list[Frame | None] = [None] * len(asked)
            if self.batching and len(asked) >= 2:
                replies = self._transact_batch([frames[i][2] for i in asked])
            for i, reply in zip(asked, replies, strict=True):
                cmd, axis, frame = frames[i]
                if reply is not None:
                    with contextlib.suppress(WrongReply):  # undecodable: asked alone below
                        values[i] = self._decode(cmd.name, frame, reply)
                        continue
                # NACKed, answered without data or unanswered: once more, on its own
                if not optional:
                    values[i] = self._request_locked(cmd.name, axis, None)
                    continue
                with contextlib.suppress(NotSupported):  # None: not asked again
                    values[i] = self.poll(cmd.name, axis)
            return values

    def _transact_batch(self, frames: list[Frame]) -> list[Frame | None]:
        """Write ``frames`` in one go; the reply to each, or None for those that got no
        data reply within :attr:`timeout` (a NACK or an ACK ends the wait for one of them:
        which one, the reply byte does not say)."""
        stream = self._stream
        if stream is None:
            raise NotConnected(f'batched read: not connected ({self.last_error})')
        self.stats['requests'] += len(frames)
        replies: list[Frame | None] = [None] * len(frames)
        waiting = len(frames)
        try:
            self._send(stream, b''.join(frame.encode() for frame in frames))
            for item in self._input_until(stream, self._last_activity + self.timeout):
                if isinstance(item, ReplyByte):
                    if not item.is_ack:
                        self.stats['nacks'] += 1
                    waiting -= 1  # one of the reads answered without data
                elif isinstance(item, Frame):
                    slot = next((i for i, frame in enumerate(frames) if replies[i] is None
                                 and (frame.opcode, frame.axis) == (item.opcode, item.axis)),
                                None)
                    if slot is None:
                        self.stats['stale'] += 1
                    else:
                        replies[slot] = item
                        waiting -= 1
                if not waiting:
                    break
        except TransportError as exc:
            self._link_lost(f'batched read: {exc}')
            raise NotConnected(f'batched read: link lost ({exc})') from exc
        if waiting == len(frames):  # not one answer: a timeout, as for a single request
            self._count_timeout('batched read')
        # each read answered (a NACK or ACK too): nothing late can come, and the controller
        # handles queued requests (those reads are named alone)
        self._count_batch(complete=not waiting)
        return replies

    def _count_batch(self, complete: bool) -> None:
        """One batch (the poll's getters, or a posted stream move) came back whole or not.
        A whole one leaves nothing late to come; ``BATCH_FAILURES`` incomplete ones in a
        row end batching for the connection (one request at a time)."""
        if complete:
            self._stale_possible = False
            self._consecutive_timeouts = 0
            self._batch_failures = 0
            return
        self.stats['incomplete_batches'] += 1
        self._batch_failures += 1
        if self._batch_failures >= BATCH_FAILURES:
            self.batching = False
            LOG.info('%d batches in a row came back incomplete: one request at a time on '
                     'this connection', self._batch_failures)

    def _transact(self, name: str, frame: Frame, expect_data: bool, timeout: float) -> Frame:
        stream = self._stream
        if stream is None:
            raise NotConnected(f'{name}: not connected ({self.last_error})')
        self.stats['requests'] += 1
        try:
            late_possible = self._send(stream, frame.encode())
            reply = self._await_reply(stream, name, frame, expect_data, timeout, late_possible)
        except TransportError as exc:
            self._link_lost(f'{name}: {exc}')
            raise NotConnected(f'{name}: link lost ({exc})') from exc
        except WrongReply:
            self._consecutive_timeouts = 0  # the device answered: it is not silent
            raise
        self._stale_possible = False
        self._consecutive_timeouts = 0
        return reply

    def _send(self, stream: ByteStream, data: bytes) -> bool:
        """Write one request (or a batch), after draining stale input if there can be any;
        until its reply is in, input may hold a stale reply again. Returns True when a late
        reply to an earlier request may still arrive (one was left unanswered).

        A posted stream move's ACKs are read first (:meth:`_settle_posted`): whoever takes
        the link next, the poll included, finds the link as if that move had been sent by
        :meth:`request`."""
        if self._posted is not None and not self._posted.settled:
            self._settle_posted(stream)
        late_possible = self._stale_possible
        if late_possible:
            self._drain(stream)
        stream.write(data)
        self._last_activity = time.monotonic()
        self._stale_possible = True
        return late_possible

    def _input_until(self, stream: ByteStream, deadline: float) -> Iterator[Frame | ReplyByte]:
        """Decoded input as it arrives, until ``deadline``; a packet left partial for
        ``resync_gap`` is given up (the decoder resynchronises). The caller stops iterating
        once it has its answer: what else came in the same read was not asked for."""
        while (remaining := deadline - time.monotonic()) > 0:
            wait = min(remaining, self.resync_gap) if self._decoder.has_partial else remaining
            data = stream.read(4096, wait)
            yield from self._decoder.feed(data) if data else self._decoder.flush_partial()

    def _drain(self, stream: ByteStream) -> None:
        """Discard stale input before a new request.

        Only a request whose reply never came (a timeout, a NACK-triggered resend, a
        connection just made) can leave a reply behind that would answer the next
        request; everything else is skipped by :meth:`_await_reply` as it reads. So the
        drain runs only then: on loopback its poll() cost 10-18 us on every transaction,
        three times before a position command reaches MOT_Update.
        """
        self._stale_possible = False
        while True:
            data = stream.read(4096, 0.0)
            if not data:
                break
            for item in self._decoder.feed(data):
                self.stats['stale'] += 1
                if isinstance(item, Frame) and 0x0700 <= item.opcode <= 0x07FF and not item.data:
                    LOG.info('controller re-sent its greeting (0x%04X)', item.opcode)

    def _await_reply(self, stream: ByteStream, name: str, frame: Frame, expect_data: bool,
                     timeout: float, late_possible: bool) -> Frame:
        """The reply to ``frame``: its data packet (getters) or the ACK (the rest).

        The other kind of reply is this request's protocol error (:class:`WrongReply`) when
        nothing else can have sent it: an ACK to a getter while no earlier request is left
        unanswered, a data packet with this request's opcode and axis to a setter. Anything
        that may be a late reply to an earlier request (a data packet of another opcode, an
        ACK after a timeout) is skipped while the real reply can still come; if nothing else
        comes, the request is named with what it got at the deadline. Only a device that
        answers nothing at all times out.
        """
        unexpected = ''  # the first answer of the wrong kind that may have been stale
        for item in self._input_until(stream, time.monotonic() + timeout):
            if isinstance(item, ReplyByte):
                if not item.is_ack:
                    self.stats['nacks'] += 1
                    raise DeviceNack(self._label(name, frame), item.code)
                if not expect_data:
                    return frame
                if not late_possible:
                    self._stale_possible = False
                    raise self._wrong_reply(name, frame, 'ACK', 'data')
                unexpected = unexpected or 'ACK'
                self.stats['stale'] += 1
            elif isinstance(item, Frame):
                if (item.opcode, item.axis) == (frame.opcode, frame.axis):
                    if expect_data:
                        return item
                    self._stale_possible = False
                    raise self._wrong_reply(name, frame, 'data', 'ACK')
                self.stats['stale'] += 1
                if not (0x0700 <= item.opcode <= 0x07FF and not item.data):  # greeting
                    unexpected = unexpected or (
                        f'data of opcode 0x{item.opcode:04X} (axis {item.axis})')
        if unexpected:
            raise self._wrong_reply(name, frame, unexpected, 'data' if expect_data else 'ACK')
        self._count_timeout(name)
        raise DeviceTimeout(f'{self._label(name, frame)}: no reply within {timeout:g} s')

    def _wrong_reply(self, name: str, frame: Frame, answer: str, expected: str) -> WrongReply:
        """Count a reply of the wrong kind for ``name`` (diagnostics, per command)."""
        self.stats['wrong_replies'] += 1
        count, _ = self.wrong_replies.get(name, (0, ''))
        error = WrongReply(self._label(name, frame), answer, expected)
        self.wrong_replies[name] = (count + 1, f'0x{frame.opcode:04X} answered {answer}, '
                                               f'expected {expected}')
        return error

    def _count_timeout(self, what: str) -> None:
        """One more unanswered request; after ``max_timeouts`` in a row the link is closed
        for the supervisor to reopen (raises :class:`NotConnected`)."""
        self.stats['timeouts'] += 1
        self._consecutive_timeouts += 1
        if self._consecutive_timeouts >= self.max_timeouts:
            self._link_lost(f'device silent: {self._consecutive_timeouts} requests unanswered')
            raise NotConnected(f'{what}: device silent, link closed for reconnect')

    @staticmethod
    def _label(name: str, frame: Frame) -> str:
        return f'{name} (axis {frame.axis})' if frame.axis else name

    def explain_nack(self, exc: DeviceNack) -> DeviceNack:
        """Add the controller's own reason (ERR_GetProtocolErrorString) to an 0xA6 NACK."""
        if exc.code != ReplyCode.INVALID_COMMAND or exc.detail:
            return exc
        try:
            detail = self.optional('ERR_GetProtocolErrorString')
        except CaptureError:  # the link went
            return exc
        return DeviceNack(exc.request, exc.code, detail) if detail else exc

    def run(self, name: str, axis: int | None = None, value: Any = None) -> Any:
        """:meth:`request`, with the controller's reason attached to an 0xA6 NACK."""
        try:
            return self.request(name, axis, value)
        except DeviceNack as exc:
            raise self.explain_nack(exc) from None

    def poll(self, name: str, axis: int | None = None) -> Any:
        """A getter the host asks on its own (identity, probes, registers, sensor polls).

        Some of these opcodes are reconstructions, and a device may lack the function. When
        the device answers 0xA6, or answers with the wrong kind of reply (an ACK: a
        controller that acknowledges what it does not know), the command lands in
        :attr:`unsupported` with that answer and is never sent again on this connection
        (:class:`NotSupported`, now and on every later call), so the host does not keep
        raising the controller's protocol-error flag; the one flag an 0xA6 raised is cleared
        again when it is the only CSR bit set (ERR_ClearErrors would otherwise also clear
        real errors). Timeouts and other NACKs raise as :meth:`request` does, for this call
        only.
        """
        answer = self.unsupported.get(name)
        if answer is not None:
            raise NotSupported(name, answer)
        opcode = f'0x{command(name).opcode:04X}'
        try:
            return self.request(name, axis)
        except WrongReply as exc:
            self._not_supported(name, f'{opcode} answered {exc.answer}, expected {exc.expected}')
            raise NotSupported(name, self.unsupported[name]) from exc
        except DeviceNack as exc:
            if exc.code != ReplyCode.INVALID_COMMAND:
                raise
            self._not_supported(name, f'{opcode} answered NACK 0xA6', exc)
            raise NotSupported(name, self.unsupported[name]) from exc

    def optional(self, name: str, axis: int | None = None) -> Any:
        """:meth:`poll`, with None for every answer that is not the value."""
        try:
            return self.poll(name, axis)
        except NotSupported:
            return None
        except (DeviceNack, DeviceTimeout) as exc:
            LOG.info('%s', exc)
            return None

    def _not_supported(self, name: str, answer: str, nack: DeviceNack | None = None) -> None:
        """Record ``name`` as unknown to the device (said once, here); for an 0xA6, with the
        device's reason, and the protocol-error flag it raised cleared."""
        self.unsupported[name] = answer  # first: explaining it asks the device again
        if nack is not None:
            detail = self.explain_nack(nack).detail
            if detail:
                self.unsupported[name] = f'{answer} "{detail}"'
        LOG.warning('%s: the device does not support it (%s); not sent again on this '
                    'connection', name, self.unsupported[name])
        if nack is not None:
            self._clear_own_protocol_error()

    def _clear_own_protocol_error(self) -> None:
        with contextlib.suppress(CaptureError, ProtocolError):
            if self.optional('ERR_CaptureSystemRegister') == CSR_PROTOCOL_ERROR:
                self.request('ERR_ClearErrors')

    # ----------------------------------------------------- device functions
    def identity(self) -> Identity:
        """Serial number, firmware, hardware and part number, best effort: blank where the
        getter is not answered with data, and how it failed in ``problems``."""
        ident = Identity()
        for attr, name in IDENTITY_GETTERS:
            try:
                value = self.poll(name)
            except NotSupported as exc:
                ident.problems[name] = exc.answer
                continue
            except (DeviceNack, DeviceTimeout) as exc:
                ident.problems[name] = str(exc)
                continue
            setattr(ident, attr, f'{value:g}' if isinstance(value, float) else str(value))
        return ident

    def read_axis(self, axis: int, with_current: bool = False) -> tuple[float, float, float | None]:
        """Load position (deg), speed (deg/s) and optionally current (mA) of one axis."""
        position = self.request('MOT_GetLoadPosition', axis)
        speed = self.request('MOT_GetMotorSpeed', axis)
        current = self.request('MOT_GetMotorCurrent', axis) if with_current else None
        return position, speed, current

    def exclusive(self) -> FairRLock:
        """The request lock, for a caller that sends a whole motion set-up (several axes)
        without the poll thread's requests in between: ``with client.exclusive(): ...``."""
        return self._lock

    def move_absolute(self, axis: int, position_deg: float, speed_deg_s: float,
                      acceleration: float) -> None:
        """The 7.1 motion profile, absolute: mode, TUM, absolute, acc, speed, position, update.

        When this client's last set-up of the axis was an absolute move and nothing else was
        commanded since, the mode commands (SetPositionMode, SetPositionAbsolute) and an
        unchanged acceleration and speed are left out. 4.2.14: without TUM "the motion
        profile will use the last parameters", and TUM builds the new profile from the
        acceleration, speed and position registers, so an unchanged register need not be
        written again.

        TUM is sent before every session ("advisable before each command session", 4.2.14),
        but for a stream of moves it is sent for the *next* session right after this one's
        MOT_Update: the 7.1 sequence already puts register writes between TUM and
        MOT_Update, and only reads (the poll) come between them here. A stream at one speed
        then costs SendPosition and MOT_Update before the device acts, and TUM after it:
        the same 3 transactions, one less round trip on the way to MOT_Update. Anything else
        commanded on the link forgets the armed TUM, and the next move sends it first again.
        """
        speed = abs(speed_deg_s)
        with self._lock:
            known = self._setups.pop(axis, None)
            same_mode = known is not None and known[0] == 'absolute'
            steps: list[tuple[str, Any]] = []
            if not same_mode:
                steps.append(('MOT_SetPositionMode', None))
            if not (same_mode and known[3]):  # no TUM armed for this session
                steps.append(('MOT_SetTum', None))
            if not same_mode:
                steps.append(('MOT_SetPositionAbsolute', None))
            if not same_mode or known[1] != acceleration:
                steps.append(('MOT_SetAcceleration', acceleration))
            if not same_mode or known[2] != speed:
                steps.append(('MOT_SetSpeed', speed))
            steps += [('MOT_SendPosition', position_deg), ('MOT_Update', None)]
            self._run_setup(axis, steps)
            self._setups[axis] = ('absolute', acceleration, speed, self._arm_tum(axis))

    def _arm_tum(self, axis: int) -> bool:
        """MOT_SetTum for the axis' next session (see :meth:`move_absolute`); False when it
        failed, so that session sends it itself (and judges an 0xA6 with the rest of its
        set-up), or when the device does not know it. The move already happened: a failure
        here is not the move's."""
        if 'MOT_SetTum' in self.unsupported:
            return False
        self._in_setup = True
        try:
            self.request('MOT_SetTum', axis)
        except CaptureError as exc:
            LOG.debug('TUM for the next move of axis %d: %s', axis, exc)
            return False
        finally:
            self._in_setup = False
        return True

    def post_moves(self, moves: dict[int, tuple[float, float, float]]) -> bool:
        """Write a stream move at once, without waiting for any reply: True when written.

        ``moves``: axis -> (position_deg, speed_deg_s, acceleration). Only the common case
        of a command stream is posted: every axis already set up by this client for
        absolute moves at this speed and acceleration, with a TUM armed (see
        :meth:`move_absolute`), so the move is MOT_SendPosition + MOT_Update per axis. They
        go out in one write, as :meth:`read_many` writes its getters (the same reading of
        the document: the controller answers requests in the order they came; and the
        same way back: :attr:`batching` off means one request at a time). False, and
        nothing written, when the link is busy (another thread holds it: never waited
        for), an earlier post is not finished, or the move needs more than that; the
        caller then sends it with :meth:`move_absolute`.

        The ACKs are read by whoever takes the link next (:meth:`_send`), and
        :meth:`finish_posted` reports them and arms the next TUM. A NACK to SendPosition
        leaves the MOT_Update that follows it to re-run the previous profile: the target
        the axis already has.
        """
        if not self._lock.acquire(blocking=False):
            return False
        try:
            stream = self._stream
            if self._posted is not None or stream is None or not self.batching:
                return False
            if any(self._setups.get(axis) != ('absolute', acceleration, abs(speed), True)
                   for axis, (_, speed, acceleration) in moves.items()):
                return False
            try:
                frames = [(name, command(name).frame(axis, value, self.group))
                          for axis, (position, _, _) in moves.items()
                          for name, value in (('MOT_SendPosition', position),
                                              ('MOT_Update', None))]
            except ProtocolError:
                return False  # move_absolute raises it, with nothing sent
            for axis, (_, speed, acceleration) in moves.items():
                self._setups[axis] = ('absolute', acceleration, abs(speed), False)
            self.stats['requests'] += len(frames)
            try:
                self._send(stream, b''.join(frame.encode() for _, frame in frames))
            except TransportError as exc:
                self._link_lost(f'stream move: {exc}')
                raise NotConnected(f'stream move: link lost ({exc})') from exc
            self._setters_sent += 1
            self.stats['posted_moves'] += 1
            self._posted = PostedMoves(dict(moves), frames, setters_at_post=self._setters_sent)
            return True
        finally:
            self._lock.release()

    def finish_posted(self) -> bool:
        """Read the ACKs of the last :meth:`post_moves` (if nobody has yet) and arm the next
        TUM; raises the device's refusal. False: an ACK was lost (or a NACK says the packet
        was not executed) and no other setter (a stop, a newer move) went out since, so the
        caller sends the moves again with :meth:`move_absolute` (the axes' set-up is
        forgotten: the whole 7.1 sequence goes out); a stale target is never sent after a
        newer setter. True: nothing to send again."""
        with self._lock:
            posted = self._posted
            if posted is None:
                return True
            try:
                if not posted.settled:  # a link that closed settled it (_close_locked)
                    self._settle_posted(self._stream)
            finally:
                self._posted = None
            superseded = self._setters_sent != posted.setters_at_post
            if posted.error is not None and (superseded or not posted.resend):
                for axis in posted.moves:
                    self._setups.pop(axis, None)
                raise posted.error
            if superseded:
                return True
            if posted.resend:
                for axis in posted.moves:
                    self._setups.pop(axis, None)
                return False
            for axis, (_, speed, acceleration) in posted.moves.items():
                if self._setups.get(axis) == ('absolute', acceleration, abs(speed), False):
                    self._setups[axis] = ('absolute', acceleration, abs(speed),
                                          self._arm_tum(axis))
            return True

    def _settle_posted(self, stream: ByteStream | None) -> None:
        """Read the ACK of each posted frame, in order (under the lock); the stream is
        there while a post is unsettled (closing the link settles it)."""
        assert stream is not None
        posted = self._posted
        assert posted is not None
        posted.settled = True
        answers: list[ReplyByte] = []
        try:
            for item in self._input_until(stream, self._last_activity + self.timeout):
                if not isinstance(item, ReplyByte):
                    self.stats['stale'] += 1
                    continue
                answers.append(item)
                if len(answers) == len(posted.frames):
                    break
        except TransportError as exc:
            self._link_lost(f'stream move: {exc}')
            posted.error = NotConnected(f'stream move: link lost ({exc})')
            return
        for (name, frame), answer in zip(posted.frames, answers, strict=False):
            if not answer.is_ack:
                self.stats['nacks'] += 1
                if posted.error is None:
                    posted.error = DeviceNack(self._label(name, frame), answer.code)
                    posted.resend = answer.code == ReplyCode.WRONG_CHECKSUM
        self._count_batch(complete=len(answers) == len(posted.frames))
        if len(answers) == len(posted.frames):
            return
        posted.resend = True
        if not answers:
            self._count_timeout('stream move')

    def jog(self, axis: int, velocity_deg_s: float, acceleration: float) -> None:
        """Speed mode (4.2.9): the axis turns at ``velocity_deg_s`` until told otherwise.

        Speed mode and an unchanged acceleration are left out when this client's last
        set-up of the axis left it in speed mode (a jog or a stop) and nothing else was
        commanded since: a stream of jog commands costs 2 round trips each, not 4.
        """
        with self._lock:
            known = self._setups.pop(axis, None)
            same_mode = known is not None and known[0] == 'speed'
            steps: list[tuple[str, Any]] = []
            if not same_mode:
                steps.append(('MOT_SetSpeedMode', None))
            if not same_mode or known[1] != acceleration:
                steps.append(('MOT_SetAcceleration', acceleration))
            steps += [('MOT_SetSpeed', velocity_deg_s), ('MOT_Update', None)]
            self._run_setup(axis, steps)
            self._setups[axis] = ('speed', acceleration, velocity_deg_s, False)

    def stop_axis(self, axis: int) -> None:
        """Decelerate to rest: speed mode with speed 0 (works from position or speed mode).
        Always the full sequence: a stop never relies on what the client remembers."""
        with self._lock:
            known = self._setups.pop(axis, None)
            self._run_setup(axis, [('MOT_SetSpeedMode', None), ('MOT_SetSpeed', 0.0),
                                   ('MOT_Update', None)])
            self._setups[axis] = ('speed', known[1] if known else None, 0.0, False)

    def _run_setup(self, axis: int, steps: list[tuple[str, Any]]) -> None:
        """Send one axis' motion set-up under the lock; the setters in it do not count as
        "something else commanded" (see :attr:`_setups`).

        An advisory step (:data:`ADVISORY_STEPS`: MOT_SetTum) refused with 0xA6 does not
        end the set-up. When the device accepts the rest, it does not know the step: it is
        recorded in :attr:`unsupported` (said once) and left out of later set-ups on this
        connection. When the rest is refused too, the 0xA6 meant the mode (scanning,
        stabilising, ...), and the set-up fails with the later refusal as before.
        """
        refused: tuple[str, DeviceNack] | None = None
        self._in_setup = True
        try:
            for name, value in steps:
                if name not in ADVISORY_STEPS:
                    self.run(name, axis, value)
                elif name not in self.unsupported:
                    try:
                        self.run(name, axis, value)
                    except DeviceNack as exc:
                        if exc.code != ReplyCode.INVALID_COMMAND:
                            raise
                        refused = (name, exc)
        finally:
            self._in_setup = False
        if refused is not None:
            name, exc = refused
            answer = f'0x{command(name).opcode:04X} answered NACK 0xA6'
            self._not_supported(name, f'{answer} "{exc.detail}"' if exc.detail else answer)
            self._clear_own_protocol_error()

    def stop_all(self, axes: list[int]) -> list[str]:
        """Stop scans, loops and every axis; returns the problems (empty when all worked)."""
        problems = []
        for name in ('SCN_StopScan', 'PRST_StopPresetLooping', 'GPS_StopTargetLooping'):
            try:
                self.request(name)
            except REQUEST_ERRORS as exc:
                LOG.debug('stop: %s', exc)
        for axis in axes:
            try:
                self.stop_axis(axis)
            except REQUEST_ERRORS as exc:
                problems.append(str(exc))
        return problems

    def reset_faults(self, axis: int) -> None:
        """4.10: "send the 'Reset faults' and the 'AxisOn' commands"."""
        self.run('MOT_ResetFaults', axis)
        self.run('MOT_AxisOn', axis)

    def registers(self, axis: int | None) -> dict[str, int]:
        """Raw per-axis registers (``axis``) or system registers (``None``): those the
        device reports; a register getter it does not answer with data is left out and
        not asked again (:meth:`poll`)."""
        wanted = [register for register in REGISTERS.values()
                  if register.per_axis == (axis is not None)]
        values = self.read_many([(register.command, axis) for register in wanted],
                                optional=True)
        return {register.name: value for register, value in zip(wanted, values, strict=True)
                if value is not None}

    def error_strings(self, csr: int) -> dict[str, str]:
        """Detailed device error text for every set CSR bit that has one (and the device
        answers with data)."""
        texts = {}
        for bit, name in CSR_ERROR_STRINGS.items():
            if csr & (1 << bit):
                try:
                    texts[name] = self.poll(name)
                except NotSupported:
                    continue
                except REQUEST_ERRORS as exc:
                    texts[name] = f'unavailable ({exc})'
        return texts

    def configure_scan(self, yaw_min: float, yaw_max: float, pitch_min: float, steps: int,
                       step_height: float, speed: float) -> None:
        """4.3: every scan parameter is sent before each scan (defaults are 0)."""
        for name, value in (
            ('SCN_SetYawMin', yaw_min), ('SCN_SetYawMax', yaw_max),
            ('SCN_SetPitchMin', pitch_min), ('SCN_SetNumSteps', steps),
            ('SCN_SetStepHeight', step_height), ('SCN_SetScanSpeed', speed),
        ):
            self.run(name, None, value)

    def start_scan(self, pattern: str) -> None:
        try:
            name = SCAN_COMMANDS[pattern]
        except KeyError:
            raise CaptureError(
                f'pattern {pattern!r} not available; the device has {sorted(SCAN_COMMANDS)}'
            ) from None
        self.run(name)

    def set_preset(self, index: int, name: str, angles: list[float]) -> None:
        full = [*angles, *([0.0] * (6 - len(angles)))][:6]
        self.run('PRST_SetPreset', index, PresetRecord(name, tuple(full)))

    def get_preset(self, index: int) -> PresetRecord:
        return self.run('PRST_GetPreset', index)

    def preset_indices(self) -> list[int]:
        flags = self.request('PRST_GetPresetFlag')
        return [bit + 1 for bit in range(15) if flags & (1 << bit)]

    def imu(self) -> dict[str, float]:
        """Euler angles (deg) and gyro rates (deg/s); :class:`NotSupported` once the device
        does not answer one of the six with data."""
        names = ('IMU_GetRoll', 'IMU_GetPitch', 'IMU_GetYaw',
                 'IMU_GetGyroX', 'IMU_GetGyroY', 'IMU_GetGyroZ')
        keys = ('roll', 'pitch', 'yaw', 'gyro_x', 'gyro_y', 'gyro_z')
        return {key: self.poll(name) for key, name in zip(keys, names, strict=True)}

    def gps_fix(self) -> tuple[bool, float, float] | None:
        """(position valid, latitude deg, longitude deg), converted from DDMM.mmmm (4.4.1);
        None once the device does not answer one of the three with data (the fix poll then
        stops); a timeout or another NACK raises, for this read only."""
        if any(name in self.unsupported for name in GPS_FIX_COMMANDS):
            return None  # nothing is sent for a fix the device cannot give
        try:
            ready, latitude, longitude = (self.poll(name) for name in GPS_FIX_COMMANDS)
        except NotSupported:
            return None
        return bool(ready), ddmm_to_degrees(latitude), ddmm_to_degrees(longitude)

    def goto_lla(self, target: int, point: GeoPoint) -> None:
        self.run('GPS_SetTargetLLA', target, point)
        self.run('GPS_GoToTarget', target)

    # ------------------------------------- issue 15: first-class device functions
    def set_tracking(self, camera: int, mode: int) -> None:
        """VDT_setTrackingOn: 0 off, 1 manual, 2 automatic (4.11.1) for camera 0..3."""
        self.run('VDT_setTrackingOn', camera, mode)

    def tracking_state(self, camera: int) -> TrackingState:
        """Tracking active, automatic mode and target detection of one camera (4.11.2-4)."""
        return TrackingState(
            camera=camera,
            active=bool(self.poll('VDT_isTrackingOn', camera)),
            automatic=bool(self.poll('VDT_isAutoModeOn', camera)),
            target_detected=bool(self.poll('VDT_isTargetDetected', camera)),
        )

    def set_axis_power(self, axis: int, on: bool) -> None:
        """MOT_AxisOn / MOT_AxisOff (4.2.11-12). Switching on also cancels the motion the
        drive buffered while off (AxisOn would resume it) by stopping the axis."""
        if on:
            self.run('MOT_AxisOn', axis)
            self.stop_axis(axis)
        else:
            self.run('MOT_AxisOff', axis)

    def digital_io(self, numbers: list[int]) -> dict[int, bool]:
        """State of digital I/O 1..6 (COM_getDigitalIO, the number in the axis byte)."""
        return {n: bool(self.poll('COM_getDigitalIO', n)) for n in numbers}

    def set_digital_output(self, number: int, on: bool) -> None:
        self.run('COM_setDigitalIO', number, int(on))

    def gps_heading(self) -> tuple[bool, float]:
        """(heading valid, system heading in compass degrees clockwise from north)."""
        ready = bool(self.poll('GPS_HeadingReady'))
        return ready, self.poll('GPS_GetHeading')

    def stored_targets(self) -> dict[int, GeoPoint]:
        """Targets 1..15 that hold a position (4.4.12: a cleared target reads all zero)."""
        targets = {}
        for number in range(1, 16):
            point = self.request('GPS_GetTargetLLA', number)
            if (point.longitude, point.latitude, point.altitude) != (0.0, 0.0, 0.0):
                targets[number] = point
        return targets


@dataclass
class TrackingState:
    """One camera's video-tracker state as the device reports it."""

    camera: int
    active: bool
    automatic: bool
    target_detected: bool

    @property
    def mode(self) -> str:
        if self.automatic:
            return 'auto'
        return 'manual' if self.active else 'off'

