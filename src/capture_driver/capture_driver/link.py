"""Capture pedestal session: handshake, request/reply, keep-alive, resync and reconnect.

One request is in flight at a time: every exchange holds the device's link lock
(:class:`~gimbal_driver_common.link_lock.LinkLock`, which the adapter passes in; a client
made alone makes its own), and so does the core's command path for its sends. A stream
move posted without waiting (:meth:`MotionRequests.post_moves`) is settled by that lock
before the link's next exchange. A request
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
import time
from collections.abc import Callable, Iterator
from typing import Any

from gimbal_driver_common.link_lock import LinkLock
from gimbal_driver_common.transport import ByteStream, TransportError
from gimbal_driver_common.unanswered import Unanswered

from .errors import CaptureError, DeviceNack, DeviceTimeout, NotConnected, WrongReply
from .protocol import (
    Frame,
    Garbage,
    ProtocolError,
    ReplyByte,
    ReplyCode,
    StreamDecoder,
    command,
)

LOG = logging.getLogger('capture_driver.client')  # the name the node's log bridge forwards


class AxisSetups:
    """What this client's last motion set-up left on each axis, shared by the link (which
    forgets it on any other setter and on close) and :class:`~.motion.MotionRequests`.

    axis -> (mode, acceleration, speed, TUM armed); armed: a TUM was sent for the next
    absolute move (see ``MotionRequests.move_absolute``).
    """

    def __init__(self) -> None:
        self.known: dict[int, tuple[str, float | None, float | None, bool]] = {}
        #: True while a set-up runs: its own setters do not make the link forget it
        self.in_setup = False

    def commanded(self) -> None:
        """A setter went out: unless it is part of a set-up, anything may have changed."""
        if not self.in_setup:
            self.known.clear()


class CaptureLink:
    """Thread-safe request/reply session with one Capture controller over any
    :class:`ByteStream`: what the client's parts (:mod:`.batch`, :mod:`.motion`,
    :mod:`.device_requests`) are handed; they use only its public names."""

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
        link_lock: LinkLock | None = None,
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
        # the device's one link lock (fair: a command stream must not starve the joint poll)
        self._lock: LinkLock = link_lock if link_lock is not None else LinkLock()
        self._stream: ByteStream | None = None
        self._decoder = StreamDecoder()
        self._connected = False
        self._connect_opcode = command('COM_Connect').opcode
        #: when the last request (or batch) was written: a reply deadline counts from it
        self.last_activity = 0.0
        self._consecutive_timeouts = 0
        # forgotten on connect and on any other command that changes something
        self.setups = AxisSetups()
        #: input may hold a reply to an earlier request (see :meth:`_drain`)
        self._stale_possible = True
        #: run under the lock on every new connection, before the handshake (the parts'
        #: per-connection state: batching)
        self.connect_hooks: list[Callable[[], None]] = []
        self.last_error = 'not connected'
        self.connects = 0
        self.stats = {'requests': 0, 'timeouts': 0, 'nacks': 0, 'wrong_replies': 0,
                      'stale': 0, 'incomplete_batches': 0, 'posted_moves': 0}
        # Commands the host sends on its own that the device answered with 0xA6 or with the
        # wrong kind of reply (name -> its answer); never sent again on this connection.
        self.unsupported: dict[str, str] = {}
        #: replies of the wrong kind per command (name -> (count, the last answer))
        self.wrong_replies: dict[str, tuple[int, str]] = {}
        #: requests the host makes on its own that went unanswered, each asked again only
        #: after its back-off (:meth:`DeviceRequests.poll`); named in diagnostics
        self.unanswered = Unanswered()
        self._keepalive_on = False

    # ---------------------------------------------------------------- link
    @property
    def lock(self) -> LinkLock:
        """The device's one link lock: every exchange holds it."""
        return self._lock

    @property
    def stream(self) -> ByteStream | None:
        """The open stream, None while not connected."""
        return self._stream

    @property
    def keepalive_on(self) -> bool:
        """The controller's keep-alive supervision was switched on at connect."""
        return self._keepalive_on

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
            for hook in self.connect_hooks:
                hook()
            self.unsupported = {}  # a new connection may be a different controller
            self.wrong_replies = {}
            self.unanswered.clear()
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
            self.request_locked('COM_setKeepAliveTimeout', None, min(timeout_ms, 0xFFFF))
            self.request_locked('COM_setKeepAliveCount', None, self.keepalive_count)
            self.request_locked('COM_StartKeepAlive', None, 1)
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
                    self.request_locked('COM_StartKeepAlive', None, 0, timeout=0.2)
            if send_disconnect and self._connected:
                with contextlib.suppress(CaptureError, TransportError, ProtocolError):
                    self.request_locked('COM_Disconnect', None, None, timeout=0.2)
            self._close_locked()

    def _close_locked(self) -> None:
        self._connected = False
        self.setups.known.clear()
        stream, self._stream = self._stream, None
        if stream is not None:
            stream.close()

    def link_lost(self, why: str) -> None:
        self.last_error = why
        if self._connected:
            LOG.warning('link lost: %s', why)
        self._close_locked()

    # ------------------------------------------------------------- requests
    def request(self, name: str, axis: int | None = None, value: Any = None,
                timeout: float | None = None, optional: bool = False) -> Any:
        """Send one table command and return its decoded reply (None for ACK-only commands).

        ``optional``: a getter the host asks on its own (a sensor, a register): asked
        once, not retried after a timeout, and its timeout does not count toward calling
        the device silent (a device that answers the rest is not silent).

        Raises :class:`ProtocolError` for bad arguments (nothing is sent),
        :class:`DeviceNack`, :class:`WrongReply`, :class:`DeviceTimeout` or
        :class:`NotConnected`.
        """
        cmd = command(name)
        with self._lock:
            return self.request_locked(cmd.name, axis, value, timeout, optional=optional)

    def request_locked(self, name: str, axis: int | None, value: Any,
                        timeout: float | None = None, group: int | None = None,
                        optional: bool = False) -> Any:
        cmd = command(name)
        # validates before anything is sent
        frame = cmd.frame(axis, value, self.group if group is None else group)
        if self._stream is None:
            raise NotConnected(f'{name}: not connected ({self.last_error})')
        if not cmd.replies_with_data:
            self.setups.commanded()  # anything may have changed an axis' mode or profile
        for attempt in (1, 2):
            try:
                reply = self._transact(name, frame, cmd.replies_with_data,
                                       self.timeout if timeout is None else timeout,
                                       optional=optional)
                return self.decode(name, frame, reply) if cmd.replies_with_data else None
            except DeviceNack as exc:
                # 0xF6: the controller did not execute the packet, so resending is safe.
                if exc.code == ReplyCode.WRONG_CHECKSUM and attempt == 1:
                    continue
                raise
            except (DeviceTimeout, WrongReply) as exc:
                # A getter changes nothing, so it is retried once (a reply of the wrong kind
                # is named only when the device gives it twice: noise can look like an ACK
                # byte); a setter is not, nor an optional getter that got no answer (it
                # would hold the link twice as long for what the device does not serve).
                retry = not (optional and isinstance(exc, DeviceTimeout))
                if cmd.replies_with_data and attempt == 1 and retry:
                    continue
                raise
        raise DeviceTimeout(f'{name}: no reply')  # pragma: no cover

    def decode(self, name: str, frame: Frame, reply: Frame) -> Any:
        """A getter's value; data that does not decode is a reply of the wrong kind."""
        try:
            return command(name).decode_reply(reply)
        except ProtocolError as exc:
            raise self._wrong_reply(name, frame, f'{len(reply.data)} data bytes ({exc})',
                                    'data') from None

    def _transact(self, name: str, frame: Frame, expect_data: bool, timeout: float,
                  optional: bool = False) -> Frame:
        stream = self._stream
        if stream is None:
            raise NotConnected(f'{name}: not connected ({self.last_error})')
        self.stats['requests'] += 1
        try:
            late_possible = self.send(stream, frame.encode())
            reply = self._await_reply(stream, name, frame, expect_data, timeout, late_possible,
                                      optional)
        except TransportError as exc:
            self.link_lost(f'{name}: {exc}')
            raise NotConnected(f'{name}: link lost ({exc})') from exc
        except WrongReply:
            self._consecutive_timeouts = 0  # the device answered: it is not silent
            raise
        self.settled()
        return reply

    def settled(self) -> None:
        """Every request written so far is answered: nothing late can come, and the device
        is not silent."""
        self._stale_possible = False
        self._consecutive_timeouts = 0

    def send(self, stream: ByteStream, data: bytes) -> bool:
        """Write one request (or a batch), after draining stale input if there can be any;
        until its reply is in, input may hold a stale reply again. Returns True when a late
        reply to an earlier request may still arrive (one was left unanswered)."""
        late_possible = self._stale_possible
        if late_possible:
            self._drain(stream)
        stream.write(data)
        self.last_activity = time.monotonic()
        self._stale_possible = True
        return late_possible

    def input_until(self, stream: ByteStream,
                    deadline: float) -> Iterator[Frame | ReplyByte | Garbage]:
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
                     timeout: float, late_possible: bool, optional: bool = False) -> Frame:
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
        for item in self.input_until(stream, time.monotonic() + timeout):
            if isinstance(item, ReplyByte):
                if not item.is_ack:
                    self.stats['nacks'] += 1
                    raise DeviceNack(self.label(name, frame), item.code)
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
        if optional:
            self.stats['timeouts'] += 1  # the device may answer the rest: not silence
        else:
            self.count_timeout(name)
        raise DeviceTimeout(f'{self.label(name, frame)}: no reply within {timeout:g} s')

    def _wrong_reply(self, name: str, frame: Frame, answer: str, expected: str) -> WrongReply:
        """Count a reply of the wrong kind for ``name`` (diagnostics, per command)."""
        self.stats['wrong_replies'] += 1
        count, _ = self.wrong_replies.get(name, (0, ''))
        error = WrongReply(self.label(name, frame), answer, expected)
        self.wrong_replies[name] = (count + 1, f'0x{frame.opcode:04X} answered {answer}, '
                                               f'expected {expected}')
        return error

    def count_timeout(self, what: str) -> None:
        """One more unanswered request; after ``max_timeouts`` in a row the link is closed
        for the supervisor to reopen (raises :class:`NotConnected`)."""
        self.stats['timeouts'] += 1
        self._consecutive_timeouts += 1
        if self._consecutive_timeouts >= self.max_timeouts:
            self.link_lost(f'device silent: {self._consecutive_timeouts} requests unanswered')
            raise NotConnected(f'{what}: device silent, link closed for reconnect')

    @staticmethod
    def label(name: str, frame: Frame) -> str:
        return f'{name} (axis {frame.axis})' if frame.axis else name

    def exclusive(self) -> LinkLock:
        """The link lock, for a caller that sends a whole motion set-up (several axes)
        without the poll thread's requests in between: ``with client.exclusive(): ...``."""
        return self._lock
