"""Which written Capture request an answer belongs to (no ROS, no I/O).

The link's reader thread decodes everything the controller sends and hands each item to
:class:`AnswerBook`. A data packet names its opcode and axis (section 3); a reply byte
(ACK, NACK) names nothing. The book gives an answer to a request only when no other
request could own it. The rules (ARCHITECTURE.md, "Reply ownership (Capture)", rules 1-6,
each a test in ``test/test_answers.py``), in short:

1. data-answered getters overlap everything, their data going to the getter of its opcode
   and axis; at most one byte-answered exchange (a setter, a getter not known to answer
   with data, or one batch whose bytes it owns as a whole) is in flight;
2. after a request gives up, the next byte-answered exchange, and the next getter of its
   opcode and axis, wait for its late answer or :data:`LATE_WINDOW_S`;
3. a NACK more than one request could own is held until one candidate is left, or given
   with :attr:`Waiting.doubt` naming the others;
4. a stop (``urgent``) never waits, and owns as a whole every byte that comes while it is
   in flight;
5. a stop preempts what it would wait for (:meth:`AnswerBook.preempt`): the requests
   written under the link lock and the setters of the exchange in flight end at once
   (:class:`~.errors.Preempted`), and nothing byte-answered is written until its hold ends;
6. a motion set-up (:meth:`AnswerBook.motion_first`) does not wait behind a read: reads
   without an answer become data-answered, other threads' byte-answered reads wait.

A read that does not wait (``on_answered``: the joint poll, ``batch.BatchedReads.ask_many``)
is told on the reader thread once each of its requests has its answer, by the same rules.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator, Sequence

from .answer_records import (
    Exchange,
    Held,
    Item,
    Request,
    Waiting,
    frame_key,
    is_greeting,
    label,
)
from .errors import Preempted
from .protocol import Frame, ReplyByte

__all__ = ['LATE_WINDOW_S', 'AnswerBook', 'Exchange', 'Held', 'Item', 'Request', 'Waiting',
           'frame_key', 'is_greeting', 'label']

#: how long after a request gave up its answer may still come (later, it is taken as lost):
#: the longest answer time the document names (SCN_StopScan, 500 ms, 4.3.9)
LATE_WINDOW_S = 0.5


class AnswerBook:
    """The requests in flight on one link, in write order; thread-safe."""

    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 late_window: float = LATE_WINDOW_S) -> None:
        self._cond = threading.Condition()
        self._clock = clock
        self.late_window = late_window
        self._seq = 0
        self._flight: list[Waiting] = []
        self._late: list[Waiting] = []
        self._held: list[Held] = []
        self._byte: Exchange | None = None
        #: (opcode, axis) of getters answered with data, or left unanswered, on this link
        self._data_keys: set[tuple[int, int]] = set()
        #: (opcode, axis) of getters the device answered with an ACK: never trusted to
        #: answer data or nothing (:meth:`_trust`)
        self._acked_keys: set[tuple[int, int]] = set()
        self.stale = 0
        self.nacks = 0
        self.greetings = 0
        #: stops that preempted the link and have not ended their hold yet
        self._stops = 0
        #: threads running a motion set-up (their own requests go; others' reads wait)
        self._motions: dict[int, int] = {}
        #: requests preempted (counted for diagnostics and tests)
        self.preempted = 0
        #: exchanges with an ``on_answered`` not called yet
        self._watched: list[Exchange] = []

    # ------------------------------------------------------------ the writers
    def reset(self, error: BaseException) -> None:
        """A new connection: what was in flight fails with ``error``, nothing is known."""
        self.fail_all(error)
        with self._cond:
            self._data_keys.clear()
            self._acked_keys.clear()

    def write(self, requests: Sequence[Request], write: Callable[[bytes], None], *,
              urgent: bool = False, block: bool = True, timeout: float = 0.0,
              holds_lock: bool = False,
              on_answered: Callable[[list[Waiting]], None] | None = None,
              ) -> list[Waiting] | None:
        """Register ``requests`` as one exchange and write them (``write``, in one call,
        under the book's lock so that write order is the book's order) once the rules
        allow; None when ``block`` is False and they do not allow it now, or ``timeout``
        s passed. ``urgent`` (a stop) goes out at once. ``holds_lock``: the writer holds
        the link lock, so a stop would wait for this request: a stop preempts it.
        ``on_answered(waitings)``: called on the reader thread once every one of them
        has its answer (never when one gives up or the link goes: the writer's to see)."""
        with self._cond:
            byte = any(not (expect_data and frame_key(frame) in self._data_keys)
                       for _, frame, expect_data in requests)
            keys = {frame_key(frame) for _, frame, expect_data in requests if expect_data}

            def allowed() -> bool:
                if not urgent and self._held_back(requests, byte):
                    if block and holds_lock and self._stops:  # the holder's next step
                        raise Preempted(f'{label(requests[0])}: not written, preempted '
                                        'by a stop')
                    return False
                self._expire()
                if any(w.expect_data and w.key in keys for w in self._late):
                    return False  # its late data would be taken for the new one's
                return not byte or (self._byte is None and not self._late_bytes())

            if not urgent and not self._wait_until(allowed, block, timeout):
                return None
            exchange = Exchange(byte=byte, urgent=urgent, on_answered=on_answered)
            if on_answered is not None:
                self._watched.append(exchange)
            if byte:
                self._take_over(exchange)
            now = self._clock()
            for name, frame, expect_data in requests:
                self._seq += 1
                exchange.waitings.append(Waiting(
                    name, frame, expect_data,
                    data_answered=expect_data and frame_key(frame) in self._data_keys,
                    written_at=now, seq=self._seq, exchange=exchange,
                    holds_lock=holds_lock))
            self._flight.extend(exchange.waitings)
            try:
                write(b''.join(frame.encode() for _, frame, _ in requests))
            except BaseException:
                self._drop(exchange.waitings)
                if exchange in self._watched:
                    self._watched.remove(exchange)
                if self._byte is exchange:
                    self._byte = None
                raise
            return exchange.waitings

    # ----------------------------------------------------------- preemption
    def preempt(self) -> None:
        """A stop needs the link now: the requests it would wait for end at once, their
        waiters raising :class:`Preempted` (those written under the link lock, and the
        setters of the byte-answered exchange in flight: a posted stream move). Until
        :meth:`preempt_done` no other byte-answered request is written: one under the
        lock raises the same, one without it waits. The stop (``urgent``) goes at once."""
        with self._cond:
            self._stops += 1
            exchange = self._byte
            targets = [w for w in (exchange.waitings if exchange is not None else [])
                       if not w.expect_data]
            targets += [w for w in self._flight if w.holds_lock]
            targets = [w for w in targets if not w.exchange.urgent]  # another stop: not cut
            self._cut_short([w for w in dict.fromkeys(targets)
                             if w.answer is None and not w.done and w in self._flight])

    def preempt_done(self) -> None:
        """The stop that preempted has ended its hold: requests go in turn again."""
        with self._cond:
            self._stops = max(0, self._stops - 1)
            self._cond.notify_all()

    @contextlib.contextmanager
    def motion_first(self) -> Iterator[None]:
        """``with book.motion_first():`` a motion set-up, on the thread that holds the link
        lock: a read in flight without its answer yet, and every getter that ended without
        one, are data-answered from now on (they no longer hold up a byte-answered
        exchange), and other threads' byte-answered reads wait until it ends."""
        me = threading.get_ident()
        with self._cond:
            self._motions[me] = self._motions.get(me, 0) + 1
            exchange = self._byte
            reads = [w for w in (exchange.waitings if exchange is not None else [])
                     if w.answer is None and not w.done]
            if exchange is not None and all(w.expect_data for w in reads) and all(
                    [self._trust(w) for w in reads]):
                self._byte = None
            for waiting in self._late:
                if waiting.expect_data:
                    self._trust(waiting)
            self._cond.notify_all()
        try:
            yield
        finally:
            with self._cond:
                self._motions[me] -= 1
                if not self._motions[me]:
                    del self._motions[me]
                self._cond.notify_all()

    def _trust(self, waiting: Waiting) -> bool:
        """A getter answers data or nothing from now on, as one left unanswered: its late
        NACK is held by the NACK rule, an ACK is never its own. Not one the device has
        answered with an ACK on this link (False: it stays byte-answered)."""
        if waiting.key in self._acked_keys:
            return False
        waiting.data_answered = True
        self._data_keys.add(waiting.key)
        return True

    def _held_back(self, requests: Sequence[Request], byte: bool) -> bool:
        """Whether a byte-answered write must not go out now: a stop preempted the link,
        or another thread's motion set-up runs and this is a read."""
        if not byte:
            return False
        if self._stops:
            return True
        others = set(self._motions) - {threading.get_ident()}
        return bool(others) and all(expect_data for _, _, expect_data in requests)

    def _cut_short(self, targets: list[Waiting]) -> None:
        """End ``targets`` now: they raise :class:`Preempted` and are late by rule (a
        setter's byte is the stop's to count; a getter keeps only its named data)."""
        now = self._clock()
        for waiting in targets:
            waiting.error = Preempted(f'{label((waiting.name, waiting.frame, False))}: '
                                      'preempted by a stop (its late answer is counted by '
                                      'rule, never given to another request)')
            waiting.superseded = waiting.done = True
            waiting.ended_at = now
            if waiting.expect_data:
                self._trust(waiting)
            self._late.append(waiting)
            self.preempted += 1
        self._flight = [w for w in self._flight if w not in targets]
        exchange = self._byte
        if exchange is not None and all(w.answer is not None or w.done
                                        for w in exchange.waitings):
            self._byte = None
        self._cond.notify_all()

    def _wait_until(self, allowed: Callable[[], bool], block: bool, timeout: float) -> bool:
        """Wait (up to ``timeout``) until ``allowed``; woken by every answer and by the
        end of each late window (time, not an answer, ends those)."""
        end = self._clock() + timeout
        while not allowed():
            left = end - self._clock()
            if not block or left <= 0.0:
                return False
            expiries = [w.ended_at + self.late_window for w in self._late
                        if w.ended_at is not None]
            if expiries:
                left = min(left, max(0.001, min(expiries) - self._clock()))
            self._cond.wait(left)
        return True

    def _take_over(self, exchange: Exchange) -> None:
        """``exchange`` becomes the byte-answered one; a stop supersedes one in flight and
        owns, as a whole, the bytes that may still come for it or for late requests."""
        old = self._byte
        now = self._clock()
        if old is not None:
            for waiting in old.waitings:
                if waiting.answer is None and not waiting.done:
                    # its byte may still come: counted with the stop's own while the stop
                    # is in flight, and it holds up the next exchange after the stop. A
                    # getter still takes its data (named), never a byte
                    waiting.superseded = True
                    if not waiting.expect_data:
                        waiting.done = True
                        waiting.ended_at = now
                        self._late.append(waiting)
        late = self._late_bytes() + [w for w in (old.waitings if old else [])
                                     if w.superseded and not w.done]
        if late:
            exchange.whole = True
            exchange.doubt = ('written while answers to ' + ', '.join(w.name for w in late)
                              + ' may come')
        self._byte = exchange
        self._cond.notify_all()

    def wait(self, waiting: Waiting, deadline: float) -> Item | None:
        """The answer to ``waiting`` by ``deadline`` (None: none came; it may come late).
        Raises the link's error when the link went first. Either way ``waiting`` leaves
        the book."""
        with self._cond:
            self._cond.wait_for(lambda: waiting.done or waiting.error is not None,
                                max(0.0, deadline - self._clock()))
            self._drop([waiting])
            if waiting.answer is None and waiting.error is not None:
                raise waiting.error
            if waiting.expect_data and isinstance(waiting.answer, ReplyByte) and (
                    waiting.answer.is_ack):
                self._acked_keys.add(waiting.key)  # a getter this device answers by ACK
            if waiting.answer is None:
                self._give_held_doubtfully(waiting)
            if waiting.answer is None and waiting.ended_at is None:
                waiting.ended_at = self._clock()
                self._late.append(waiting)
                if waiting.expect_data and waiting.data_answered is False:
                    self._data_keys.add(waiting.key)  # it answers nothing: it may overlap
            self._end_exchange(waiting.exchange)
            return waiting.answer

    def _give_held_doubtfully(self, waiting: Waiting) -> None:
        for held in self._held:
            if waiting in held.candidates:
                others = [w.name for w in held.candidates if w is not waiting]
                waiting.answer = held.byte
                waiting.doubt = 'may be the answer of ' + ', '.join(others)
                held.candidates.remove(waiting)
                held.candidates[:] = [w for w in held.candidates if w.answer is None]
                for other in held.candidates:  # void: nobody else gets it for certain
                    other.doubt = other.doubt or f'a NACK {waiting.name} also may own'
                self._held.remove(held)
                batch = held.batch
                if batch is not None:  # it owns the rest of its bytes as a whole
                    pending, batch.pending = batch.pending or [], None
                    batch.whole = True
                    batch.doubt = (f'a NACK came that {waiting.name} and '
                                   + ', '.join(others) + ' may own')
                    if waiting not in batch.waitings:
                        batch.received.append(held.byte)
                    for byte in pending:
                        self._deliver_byte(byte, counted=True)
                return

    def _end_exchange(self, exchange: Exchange) -> None:
        if self._byte is exchange and all(w.done or w.ended_at is not None or
                                          w not in self._flight for w in exchange.waitings):
            self._byte = None
            self._cond.notify_all()

    def dropped(self, waitings: Sequence[Waiting]) -> None:
        """``waitings`` gave up and were never taken by the device (the batch reads of a
        controller that drops what it queues): no late answer is waited for."""
        with self._cond:
            self._late = [w for w in self._late if w not in waitings]
            self._cond.notify_all()

    def answer_with_data(self, frames: Sequence[Frame]) -> bool:
        """Every one of these getters is data-answered on this link: written, none takes
        a byte-answered exchange's place (their answer is their data, or nothing)."""
        with self._cond:
            return all(frame_key(frame) in self._data_keys for frame in frames)

    def in_flight(self) -> list[str]:
        """The names of the requests waiting for an answer (diagnostics, tests)."""
        with self._cond:
            return [w.name for w in self._flight if not w.done]

    def idle(self) -> bool:
        """Nothing in flight."""
        with self._cond:
            return not self._flight

    @property
    def late_possible(self) -> bool:
        """A request ended without its answer, and that answer may still come."""
        with self._cond:
            self._expire()
            return bool(self._late)

    def fail_all(self, error: BaseException) -> None:
        """The link is gone: every request in flight raises ``error``."""
        with self._cond:
            for waiting in self._flight:
                if not waiting.done:
                    waiting.error = error
            self._flight.clear()  # nothing of that link answers anything any more
            self._late.clear()
            self._held.clear()
            self._watched.clear()
            self._byte = None
            self._cond.notify_all()

    def _drop(self, waitings: list[Waiting]) -> None:
        self._flight = [w for w in self._flight if w not in waitings]
        self._cond.notify_all()

    def _expire(self) -> None:
        now = self._clock()
        self._late = [w for w in self._late
                      if w.ended_at is not None and now - w.ended_at < self.late_window]

    def _late_bytes(self) -> list[Waiting]:
        """Late requests whose byte may still come (any late request may be NACKed, but
        only byte-answered ones hold up the next exchange: the others are held)."""
        return [w for w in self._late if not w.data_answered]

    # ------------------------------------------------------------ the reader
    def deliver(self, item: Item) -> bool:
        """Give ``item`` to the request it answers; False when none did (stale: a reply
        that came after its request gave up, or noise that decoded; counted)."""
        return self.deliver_all([item]) == 1

    def deliver_all(self, items: Sequence[Item]) -> int:
        """:meth:`deliver` each of ``items`` (what one read of the link decoded) in order,
        under one hold of the lock; how many were taken. An exchange's ``on_answered`` is
        called after, outside the lock."""
        taken = 0
        with self._cond:
            self._expire()
            for item in items:
                if (self._deliver_byte(item) if isinstance(item, ReplyByte)
                        else self._deliver_data(item)):
                    taken += 1
                else:
                    self.stale += 1
                self._resolve()
            answered = [exchange for exchange in self._watched
                        if all(w.done and w.answer is not None for w in exchange.waitings)]
            for exchange in answered:
                self._watched.remove(exchange)
            self._cond.notify_all()
        for exchange in answered:  # outside the lock: they take their answers
            if exchange.on_answered is not None:
                exchange.on_answered(exchange.waitings)
        return taken

    def take(self, waitings: Sequence[Waiting]) -> list[Item | None]:
        """The answers of ``waitings`` that ``on_answered`` reported, which leave the book
        (:meth:`wait` for each, under one hold of the lock)."""
        with self._cond:
            if all(w.done and w.answer is not None and w.error is None for w in waitings):
                self._drop(list(waitings))
                for waiting in waitings:
                    self._end_exchange(waiting.exchange)
                return [w.answer for w in waitings]
        return [self.wait(w, 0.0) for w in waitings]

    def _deliver_data(self, item: Frame) -> bool:
        if is_greeting(item):
            self.greetings += 1
            return False
        key = (item.opcode, item.axis)
        # the oldest getter that may still be answered, a late one first; else a setter
        # of that opcode (data where an ACK belongs)
        getters = sorted((w for w in self._late + self._flight
                          if w.key == key and w.expect_data and w.answer is None),
                         key=lambda w: w.seq)
        setters = [w for w in self._flight if w.key == key and w.answer is None]
        target = getters[0] if getters else (setters[0] if setters else None)
        if target is None:
            busy = [w for w in self._flight if not w.done]
            if len(busy) == 1:  # alone on the link: name what it got if nothing else comes
                busy[0].unexpected = busy[0].unexpected or (
                    f'data of opcode 0x{item.opcode:04X} (axis {item.axis})')
            return False
        if target.expect_data:
            self._data_keys.add(key)
        if target in self._late:
            self._late.remove(target)
            target.answer = item
            return False  # the late data of a request that gave up: stale
        self._resolve_one(target, item)
        return True

    def _deliver_byte(self, item: ReplyByte, counted: bool = False) -> bool:
        if not item.is_ack and not counted:
            self.nacks += 1
        exchange = self._byte
        if exchange is not None and exchange.pending is not None:
            exchange.pending.append(item)  # counted once the held NACK has its owner
            return True
        if exchange is not None and exchange.whole:
            exchange.received.append(item)
            slot = self._slot(exchange)
            if slot is not None:
                slot.doubt = exchange.doubt
                self._resolve_one(slot, item)
            return True
        slot = self._slot(exchange) if exchange is not None else None
        candidates = [slot] if slot is not None else []
        candidates += [w for w in self._late if item.is_ack is False or not w.data_answered]
        if not item.is_ack:  # a NACK may answer a data-answered getter too
            candidates += [w for w in self._flight if w.expect_data and w.data_answered
                           and w.answer is None and w is not slot]
        if not candidates:
            lone = [w for w in self._flight if not w.done]
            if item.is_ack and len(lone) == 1:
                lone[0].unexpected = lone[0].unexpected or 'ACK'
            return False
        if len(candidates) > 1 and all(w in self._late for w in candidates):
            self._late.remove(min(candidates, key=lambda w: w.seq))  # stale either way
            return False
        if len(candidates) > 1:
            batch = exchange if slot is not None and exchange is not None and len(
                exchange.waitings) > 1 else None
            if batch is not None:  # a batch cannot count past a byte it may not own
                batch.pending = []
            self._held.append(Held(item, candidates, batch))
            return True
        [target] = candidates
        if target in self._late:
            self._late.remove(target)
            target.answer = item
            return False
        if exchange is not None and target in exchange.waitings:
            exchange.received.append(item)
        self._resolve_one(target, item)
        return True

    def _slot(self, exchange: Exchange) -> Waiting | None:
        """The next request of a byte-answered exchange to count a byte for."""
        return next((w for w in exchange.waitings if w.answer is None and not w.done
                     and not w.superseded and w in self._flight), None)

    def _resolve(self) -> None:
        """Give each held NACK to its last candidate (the others answered or expired),
        until none is left to give (a batch's counting may settle another)."""
        while self._resolve_once():
            pass

    def _resolve_once(self) -> bool:
        for held in list(self._held):
            held.candidates[:] = [w for w in held.candidates if w.answer is None and (
                w in self._flight or w in self._late)]
            if len(held.candidates) <= 1:
                self._held.remove(held)
                if held.candidates:
                    [target] = held.candidates
                    if target in self._late:
                        self._late.remove(target)
                        target.answer = held.byte
                        self.stale += 1
                    else:
                        if target.exchange.byte:
                            target.exchange.received.append(held.byte)
                        self._resolve_one(target, held.byte)
                else:
                    self.stale += 1
                batch = held.batch
                if batch is not None:  # its counting goes on from the byte it waited for
                    pending, batch.pending = batch.pending or [], None
                    for byte in pending:
                        self._deliver_byte(byte, counted=True)
                return True
        return False

    @staticmethod
    def _resolve_one(waiting: Waiting, item: Item) -> None:
        waiting.answer = item
        waiting.done = True
