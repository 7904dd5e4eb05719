"""Capture pedestal link: one reader thread, handshake, requests, resync and reconnect.

The link has one owner of its input: the reader thread ``capture-reader`` (the session
base, :class:`gimbal_driver_common.session.Session`, as every streaming client has). It
decodes everything the controller sends and hands it to :class:`~.answers.AnswerBook`,
which gives an answer only to the one request that can own it (the rules are in
:mod:`.answers`): data packets name their getter; at most one byte-answered exchange (a
setter, a getter not yet answered with data, a stop's batch) is in flight, and after a
request gives up the next one waits until its late answer came or the late window
passed. Callers write their requests and wait for their own answers; nobody reads the
link but the reader. So the joint poll's getters go out while a setter or a slow sensor
read waits, and a stop goes out at once: asking for the link lock, it preempts the
exchange of the lock's holder (the lock's ``preempt`` hook,
:meth:`.answers.AnswerBook.preempt`: that waiter raises :class:`~.errors.Preempted`, the
holder gives the lock up, a late answer is the stop's to count); a motion set-up does not
wait behind a sensor read either (:meth:`.answers.AnswerBook.motion_first`). Setters go
one sequence at a time: they hold the device's link lock
(:class:`~gimbal_driver_common.link_lock.LinkLock`, which the adapter passes in; a client
made alone makes its own), and so does the core's command path for its sends; a stream
move posted without waiting (:meth:`MotionRequests.post_moves`) is settled by that lock
before the next setter. A controller that drops what it queues (batched reads that come
back incomplete, see :mod:`.batch`) is driven one request at a time instead: then every
request holds the lock (:attr:`CaptureLink.overlap` off).

A getter is answered by its data packet, a setter by a single ACK byte; a NACK byte raises
:class:`DeviceNack` carrying the spec's meaning and advice. A reply of the other kind (an
ACK to a getter, data to a setter) raises :class:`WrongReply`: the device answered, so it
is a protocol error of that request, never silence; only no answer at all is a
:class:`DeviceTimeout`, and only a device that answers nothing at all for ``max_timeouts``
request timeouts, while requests the driver needs wait, has its link closed ("device
silent"; requests in flight together during one stall count once). Garbage and corrupted
or truncated packets are skipped by :class:`~.protocol.StreamDecoder`; if a started
packet stalls for ``resync_gap`` the reader gives it up and rescans, so a lost byte costs
at most one request.

Requests the host makes on its own (identity, probes, the status registers, the sensor
polls: :class:`~.device_requests.Polls`) stop being sent once the device answered one
with 0xA6 or with the wrong kind of reply (:attr:`unsupported`), and are asked again
after a growing back-off when unanswered (:attr:`unanswered`); so does the one advisory
step of a move, MOT_SetTum (4.2.14, 7.1 "as needed").

Handshake (section 6.1): over TCP the controller sends a COM_Connect packet as soon as the
connection opens; the client answers with a COM_Connect packet carrying the opcode the
controller used (so a wrong reconstruction of that opcode cannot break the handshake) and
waits for the ACK. On a serial line there is no greeting; the client sends COM_Connect.

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
from collections.abc import Callable, Sequence
from typing import Any

from gimbal_driver_common.errors import LinkError
from gimbal_driver_common.link_lock import LinkLock
from gimbal_driver_common.session import Protocol, Session, StreamLink
from gimbal_driver_common.transport import ByteStream, TransportError
from gimbal_driver_common.unanswered import Unanswered

from .answers import AnswerBook, Request, Waiting, is_greeting
from .errors import (
    CaptureError,
    DeviceNack,
    DeviceTimeout,
    NotConnected,
    Preempted,
    WrongReply,
)
from .protocol import (
    Frame,
    ProtocolError,
    ReplyByte,
    ReplyCode,
    StreamDecoder,
    command,
)

LOG = logging.getLogger('capture_driver.client')  # the name the node's log bridge forwards

#: requests after which the controller may take this long (s) before it answers them and
#: handles anything new: 4.3.9 "Stop scan can take up to 500 milliseconds before sending
#: ACK and handle new incoming commands". Its second witness, a public CapTrack Wireshark
#: dissector (port 4949), agrees on the opcodes (0x0408 SCN_StopScan) and names no time.
BUSY_AFTER = {'SCN_StopScan': 0.5}
#: what the driver adds to a documented answer time before it calls a request unanswered
ANSWER_MARGIN_S = 0.3


def answer_time(name: str) -> float:
    """The least time to wait for ``name``'s answer: the document's time plus a margin
    (0 for requests the document gives no time: the request timeout applies)."""
    return BUSY_AFTER[name] + ANSWER_MARGIN_S if name in BUSY_AFTER else 0.0



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


class CaptureLink(Protocol):
    """Thread-safe request/reply link with one Capture controller over any
    :class:`ByteStream`: what the client's parts (:mod:`.batch`, :mod:`.motion`,
    :mod:`.device_requests`) are handed; they use only its public names. It is the
    session's protocol: the reader thread calls :meth:`data_received` and :meth:`tick`."""

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
        # the device's one link lock: setters hold it (fair, and a stop goes first)
        self._lock: LinkLock = link_lock if link_lock is not None else LinkLock()
        self._stream: ByteStream | None = None
        self._session: Session | None = None
        self._decoder = StreamDecoder()
        self._last_input = 0.0
        self.answers = AnswerBook()
        # a stop asking for the lock ends the exchange in flight at once (see .answers)
        self._lock.preempt = self.answers.preempt
        self._lock.preempt_done = self.answers.preempt_done
        self._greeting: Frame | None = None
        self._greeted = threading.Event()
        self._connected = False
        self._connect_opcode = command('COM_Connect').opcode
        #: when the last request (or batch) was written
        self.last_activity = 0.0
        #: until when the controller may hold every answer (after SCN_StopScan, 4.3.9)
        self._busy_until = 0.0
        #: when the device last answered anything (the handshake, any request)
        self._last_answer = 0.0
        #: requests may overlap (see :mod:`.answers`); off for a controller that drops what
        #: it queues (the batched reads' way back): then every request holds the lock
        self.overlap = True
        # forgotten on connect and on any other command that changes something
        self.setups = AxisSetups()
        #: run under the lock on every new connection, before the handshake (the parts'
        #: per-connection state: batching)
        self.connect_hooks: list[Callable[[], None]] = []
        self.last_error = 'not connected'
        self.connects = 0
        self._stats = {'requests': 0, 'timeouts': 0, 'wrong_replies': 0,
                       'incomplete_batches': 0, 'posted_moves': 0}
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
    def link_lock(self) -> LinkLock:
        """The device's one link lock (``Device.link_lock``): every setter sequence holds
        it; a caller that sends a whole motion set-up (several axes) without another setter
        in between holds it around them: ``with client.link_lock: ...``."""
        return self._lock

    @property
    def stream(self) -> ByteStream | None:
        """The open stream, None while not connected."""
        return self._stream

    @property
    def stats(self) -> dict[str, int]:
        """Link counters for diagnostics (the reader's included)."""
        return {**self._stats, 'nacks': self.answers.nacks, 'stale': self.answers.stale}

    def count(self, name: str, by: int = 1) -> None:
        """Add to one of the link's own counters (:attr:`stats`)."""
        self._stats[name] += by

    @property
    def keepalive_on(self) -> bool:
        """The controller's keep-alive supervision was switched on at connect."""
        return self._keepalive_on

    @property
    def connected(self) -> bool:
        """Handshake done and the reader still up (it may have just found the link gone)."""
        session = self._session
        return self._connected and session is not None and session.alive

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
            self.answers.reset(NotConnected('a new connection was made'))
            self.overlap = True
            for hook in self.connect_hooks:
                hook()
            self.unsupported = {}  # a new connection may be a different controller
            self.wrong_replies = {}
            self.unanswered.clear()
            self._keepalive_on = False
            self._greeting = None
            self._greeted.clear()
            self._last_answer = time.monotonic()
            self._session = Session(StreamLink(stream), self, 'capture', read_timeout=0.02,
                                    link_error=NotConnected).start()
            try:
                self._handshake()
                self._connected = True
                if self.keepalive_period > 0:
                    self._configure_keepalive()
            except (CaptureError, TransportError, LinkError) as exc:
                self.last_error = f'handshake with {stream.description} failed: {exc}'
                self._close_locked()
                raise NotConnected(self.last_error) from exc
            self.connects += 1
            self.last_error = ''
        LOG.info('connected to %s', self.description)

    def _handshake(self) -> None:
        if self.expect_greeting and self._greeted.wait(self.greeting_timeout):
            greeting = self._greeting
            if greeting is not None:
                self._connect_opcode = greeting.opcode
        frame = Frame(self.group, 0, self._connect_opcode)
        self._transact('COM_Connect', frame, expect_data=False, timeout=self.timeout)

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
        session, self._session = self._session, None
        self._stream = None
        if session is not None:
            session.close()  # the reader closes the stream as it ends
        self.answers.fail_all(NotConnected(f'link closed ({self.last_error or "closed"})'))

    def link_lost(self, why: str) -> None:
        """Give the link up (from a caller's thread): the supervisor reconnects."""
        self.last_error = why
        if self._connected:
            LOG.warning('link lost: %s', why)
        self._connected = False
        session = self._session
        if session is not None:
            session.lose(NotConnected(why))

    # ------------------------------------------------- the reader (Protocol)
    def data_received(self, data: bytes) -> None:
        self._last_input = time.monotonic()
        self._take(self._decoder.feed(data))

    def tick(self, now: float) -> float | None:
        """Give up a packet left partial for ``resync_gap`` (the decoder rescans)."""
        if not self._decoder.has_partial:
            return None
        if now - self._last_input >= self.resync_gap:
            self._take(self._decoder.flush_partial())
            return None
        return self._last_input + self.resync_gap

    def connection_lost(self, error: LinkError | None) -> None:
        if error is None:
            return
        if self._connected:
            LOG.warning('link lost: %s', error)
        self.last_error = str(error)
        self._connected = False
        self.answers.fail_all(NotConnected(f'link lost ({error})'))

    def _take(self, items: Sequence[object]) -> None:
        answers: list[Frame | ReplyByte] = []
        for item in items:
            if not isinstance(item, Frame | ReplyByte):
                continue  # garbage: counted by the decoder
            if isinstance(item, Frame) and is_greeting(item):
                if not self._greeted.is_set():
                    self._greeting = item
                    self._greeted.set()
                else:
                    LOG.info('controller re-sent its greeting (0x%04X)', item.opcode)
                continue
            answers.append(item)
        if answers and self.answers.deliver_all(answers):
            self._last_answer = time.monotonic()  # the device answers: not silent

    # ------------------------------------------------------------- requests
    def request(self, name: str, axis: int | None = None, value: Any = None,
                timeout: float | None = None, optional: bool = False) -> Any:
        """Send one table command and return its decoded reply (None for ACK-only commands).

        A getter goes out at once, beside others in flight (:attr:`overlap`); a setter
        holds the link lock. ``optional``: a getter the host asks on its own (a sensor, a
        register): asked once, not retried after a timeout, and its timeout does not count
        toward calling the device silent (a device that answers the rest is not silent).

        Raises :class:`ProtocolError` for bad arguments (nothing is sent),
        :class:`DeviceNack`, :class:`WrongReply`, :class:`DeviceTimeout` or
        :class:`NotConnected`.
        """
        cmd = command(name)
        if cmd.replies_with_data and self.overlap:
            return self.request_locked(cmd.name, axis, value, timeout, optional=optional)
        with self._lock:
            return self.request_locked(cmd.name, axis, value, timeout, optional=optional)

    def request_locked(self, name: str, axis: int | None, value: Any,
                       timeout: float | None = None, group: int | None = None,
                       optional: bool = False) -> Any:
        """:meth:`request` for a caller that holds the link lock where one is needed (a
        setter, or any request while :attr:`overlap` is off)."""
        cmd = command(name)
        # validates before anything is sent
        frame = cmd.frame(axis, value, self.group if group is None else group)
        if self._session is None:
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
                if exc.code == ReplyCode.WRONG_CHECKSUM and attempt == 1 and not exc.doubt:
                    continue
                raise
            except Preempted:
                raise  # a stop needs the link: not sent again before it
            except (DeviceTimeout, WrongReply) as exc:
                # A getter changes nothing, so it is retried once (a reply of the wrong kind
                # is named only when the device gives it twice: noise can look like an ACK
                # byte); a setter is not, nor an optional getter that got no answer (it
                # would hold its caller twice as long for what the device does not serve).
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
            raise self.wrong_reply(name, frame, f'{len(reply.data)} data bytes ({exc})',
                                   'data') from None

    def write(self, requests: Sequence[Request], block: bool = True,
              urgent: bool = False,
              on_answered: Callable[[list[Waiting]], None] | None = None,
              ) -> list[Waiting] | None:
        """Write ``requests`` in one write, registered for their answers (see
        :class:`~.answers.AnswerBook` for when they may go out); None when ``block`` is
        False and they may not go out now. A stop (``urgent``, or the link lock held
        urgently) goes out at once. ``on_answered``: see :meth:`AnswerBook.write`."""
        session = self._session
        if session is None or not session.alive:
            lost = session.error if session is not None else None
            raise NotConnected(f'{requests[0][0]}: link lost ({lost})' if lost is not None
                               else f'{requests[0][0]}: not connected ({self.last_error})')
        started = time.monotonic()
        try:
            waitings = self.answers.write(
                requests, session.write, urgent=urgent or self._lock.held_urgently(), block=block,
                timeout=2 * self.timeout + 1.0, holds_lock=self._lock.held(),
                on_answered=on_answered)
        except LinkError as exc:
            raise NotConnected(f'{requests[0][0]}: link lost ({exc})') from exc
        # time spent waiting for the link to resynchronise is not the device's silence, up
        # to the moment the request was written: from then on its wait counts (written_at
        # starts its deadline), however long the write call itself took (a starved thread)
        written = waitings[0].written_at if waitings else time.monotonic()
        self._last_answer += max(0.0, written - started)
        if waitings is None:
            if block:
                raise DeviceTimeout(f'{requests[0][0]}: the link stayed busy')
            return None
        self._stats['requests'] += len(requests)
        self.last_activity = time.monotonic()
        for waiting in waitings:
            if waiting.name in BUSY_AFTER:
                self._busy_until = max(self._busy_until,
                                       waiting.written_at + BUSY_AFTER[waiting.name])
        return waitings

    def answer(self, waiting: Waiting, deadline: float) -> Frame | ReplyByte | None:
        """The answer to a written request by ``deadline``, None if none came."""
        try:
            return self.answers.wait(waiting, deadline)
        except LinkError as exc:
            raise NotConnected(f'{waiting.name}: link lost ({exc})') from exc

    def _transact(self, name: str, frame: Frame, expect_data: bool, timeout: float,
                  optional: bool = False) -> Frame:
        [waiting] = self.write([(name, frame, expect_data)]) or []
        timeout = max(timeout, answer_time(name))
        answer = self.answer(waiting, self.deadline(waiting, timeout))
        if waiting.superseded and answer is None:
            raise DeviceTimeout(f'{self.label(name, frame)}: a stop went out before its '
                                'answer came (its answer can no longer be told apart)')
        if isinstance(answer, ReplyByte):
            if not answer.is_ack:
                raise DeviceNack(self.label(name, frame), answer.code, doubt=waiting.doubt)
            if expect_data:
                raise self.wrong_reply(name, frame, 'ACK', 'data')
        elif isinstance(answer, Frame):
            if not expect_data:
                raise self.wrong_reply(name, frame, 'data', 'ACK')
        elif waiting.unexpected:
            raise self.wrong_reply(name, frame, waiting.unexpected,
                                   'data' if expect_data else 'ACK')
        else:
            if optional:
                self._stats['timeouts'] += 1  # the device may answer the rest: not silence
            else:
                self.count_timeout(name)
            raise DeviceTimeout(f'{self.label(name, frame)}: no reply within {timeout:g} s')
        return answer if isinstance(answer, Frame) else frame

    def deadline(self, waiting: Waiting, timeout: float) -> float:
        """When ``waiting`` gives up: ``timeout`` after it was written, and later by what
        remains of a scan stop's busy time then (4.3.9: the controller handles new
        commands up to 500 ms after SCN_StopScan)."""
        return waiting.written_at + timeout + max(0.0, self._busy_until - waiting.written_at)

    def wrong_reply(self, name: str, frame: Frame, answer: str, expected: str) -> WrongReply:
        """Count a reply of the wrong kind for ``name`` (diagnostics, per command)."""
        self._stats['wrong_replies'] += 1
        count, _ = self.wrong_replies.get(name, (0, ''))
        error = WrongReply(self.label(name, frame), answer, expected)
        self.wrong_replies[name] = (count + 1, f'0x{frame.opcode:04X} answered {answer}, '
                                               f'expected {expected}')
        return error

    def count_timeout(self, what: str) -> None:
        """One more unanswered request the driver needs. When the device has answered
        nothing at all for ``max_timeouts`` request timeouts (the time of that many
        requests unanswered one after the other; requests in flight together during one
        stall count once) the link is closed for the supervisor to reopen (raises
        :class:`NotConnected`)."""
        self._stats['timeouts'] += 1
        silent_for = time.monotonic() - self._last_answer
        if silent_for + 1e-3 >= self.max_timeouts * self.timeout:
            self.link_lost(f'device silent: no answer for {silent_for:.1f} s '
                           f'({self.max_timeouts} request timeouts)')
            raise NotConnected(f'{what}: device silent, link closed for reconnect')

    @staticmethod
    def label(name: str, frame: Frame) -> str:
        return f'{name} (axis {frame.axis})' if frame.axis else name
