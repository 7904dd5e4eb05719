"""Which written Capture request an answer belongs to (no ROS, no I/O).

The link's reader thread decodes everything the controller sends and hands each item to
:class:`AnswerBook`, which gives it to the request it answers. A data packet names its
opcode and axis (section 3), so getters can be in flight together and each finds its
reply. A reply byte (ACK, NACK) names nothing: it goes to the oldest setter in flight, and
only when no setter is in flight to the oldest getter (a getter answered by a byte: a NACK,
or the ACK of a controller that acknowledges what it does not know). So the book lets
requests overlap only where that rule cannot give a byte to the wrong one:

- getters overlap each other (a byte among them is named by asking the read alone);
- setters go one sequence at a time (the caller holds the link lock) and overlap only the
  getters the device has answered with data on this connection (*trusted*: they answer
  with data, not a byte) or has left unanswered before (they answer nothing);
- a getter not trusted yet waits while a setter is in flight, and a setter waits while
  such a getter is in flight (one round trip, or that getter's timeout once per
  connection);
- a stop (the link lock held urgently) waits for nothing: it goes out while any read
  waits for its answer. Should an untrusted getter's NACK come first, the stop takes it
  and the getter times out: rare, and the stop is on the wire at once either way. A stop
  does wait for the link lock itself: when a setter sequence holds it and waits for an
  untrusted getter (once per getter and connection), the stop comes after that wait.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from .protocol import Frame, ReplyByte

#: a request to write: (command name for messages, its frame, True when it takes data)
Request = tuple[str, Frame, bool]
Item = Frame | ReplyByte


def is_greeting(item: Frame) -> bool:
    """The controller's COM_Connect packet (section 6.1): sent on its own, never an answer."""
    return 0x0700 <= item.opcode <= 0x07FF and not item.data


@dataclass(eq=False)
class Waiting:
    """One written request until it has its answer (or gives up)."""

    name: str
    frame: Frame
    expect_data: bool
    #: a getter that answers with data (see the module docstring); setters: True
    trusted: bool
    written_at: float = 0.0
    #: what answered it: its data packet or a reply byte (None: nothing yet)
    answer: Item | None = None
    #: the first answer of the wrong kind that may have been a late reply to an earlier
    #: request (a getter named with it at its deadline, instead of a timeout)
    unexpected: str = ''
    error: BaseException | None = None
    done: bool = field(default=False)

    @property
    def key(self) -> tuple[int, int]:
        return frame_key(self.frame)


class AnswerBook:
    """The requests in flight on one link, in write order; thread-safe."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._cond = threading.Condition()
        self._clock = clock
        self._in_flight: list[Waiting] = []
        #: (opcode, axis) of getters answered with data, or left unanswered, on this link
        self._trusted: set[tuple[int, int]] = set()
        #: requests that ended without their answer whose reply may still come
        self._late = 0
        self.stale = 0
        self.nacks = 0
        self.greetings = 0

    # ------------------------------------------------------------ the writers
    def reset(self, error: BaseException) -> None:
        """A new connection: what was in flight fails with ``error``, nothing is trusted."""
        self.fail_all(error)
        with self._cond:
            self._trusted.clear()
            self._late = 0

    def write(self, requests: Sequence[Request], write: Callable[[bytes], None], *,
              urgent: bool = False, block: bool = True, timeout: float = 0.0,
              ) -> list[Waiting] | None:
        """Register ``requests`` and write them (``write``, in one call, under the book's
        lock so that write order is the book's order) once the overlap rules allow;
        None when ``block`` is False and they do not allow it now, or ``timeout`` s
        passed (a stuck request ends at its own deadline, so this is a bound only)."""
        with self._cond:
            setters = any(not expect_data for _, _, expect_data in requests)
            untrusted = any(expect_data and frame_key(frame) not in self._trusted
                            for _, frame, expect_data in requests)

            def allowed() -> bool:
                busy = [w for w in self._in_flight if not w.done]
                if setters and not urgent and any(w.expect_data and not w.trusted
                                                  for w in busy):
                    return False
                return not (untrusted and any(not w.expect_data for w in busy))

            if not allowed() and not (block and self._cond.wait_for(allowed, timeout)):
                return None
            now = self._clock()
            waitings = [Waiting(name, frame, expect_data,
                                trusted=not expect_data or frame_key(frame) in self._trusted,
                                written_at=now)
                        for name, frame, expect_data in requests]
            self._in_flight.extend(waitings)
            try:
                write(b''.join(frame.encode() for _, frame, _ in requests))
            except BaseException:
                self._drop(waitings)
                raise
            return waitings

    def wait(self, waiting: Waiting, deadline: float) -> Item | None:
        """The answer to ``waiting`` by ``deadline`` (None: none came; it may come late).
        Raises the link's error when the link went first. Either way ``waiting`` leaves
        the book."""
        with self._cond:
            self._cond.wait_for(lambda: waiting.done or waiting.error is not None,
                                max(0.0, deadline - self._clock()))
            self._drop([waiting])
            if waiting.answer is None:
                if waiting.error is not None:
                    raise waiting.error
                self._late += 1
                if waiting.expect_data:  # it answers nothing: overlapping it is safe
                    self._trusted.add(waiting.key)
            return waiting.answer

    def in_flight(self) -> list[str]:
        """The names of the requests waiting for an answer (diagnostics, tests)."""
        with self._cond:
            return [w.name for w in self._in_flight if not w.done]

    def idle(self) -> bool:
        """Nothing in flight."""
        with self._cond:
            return not self._in_flight

    def settled(self) -> None:
        """Everything written so far is answered: no late reply can come any more."""
        with self._cond:
            if not self._in_flight:
                self._late = 0

    @property
    def late_possible(self) -> bool:
        """A request ended without its answer, and that answer may still come."""
        with self._cond:
            return self._late > 0

    def fail_all(self, error: BaseException) -> None:
        """The link is gone: every request in flight raises ``error``."""
        with self._cond:
            for waiting in self._in_flight:
                if not waiting.done:
                    waiting.error = error
            self._in_flight.clear()  # nothing of that link answers anything any more
            self._cond.notify_all()

    def _drop(self, waitings: list[Waiting]) -> None:
        self._in_flight = [w for w in self._in_flight if w not in waitings]
        self._cond.notify_all()

    # ------------------------------------------------------------ the reader
    def deliver(self, item: Item) -> bool:
        """Give ``item`` to the request it answers; False when none did (stale: a reply
        that came after its request gave up, or noise that decoded; counted)."""
        with self._cond:
            target = self._target(item)
            if target is None:
                self.stale += 1
                if self._late:
                    self._late -= 1  # the late reply has come
                return False
            self._cond.notify_all()
            return True

    def _target(self, item: Item) -> Waiting | None:
        busy = [w for w in self._in_flight if not w.done]
        if isinstance(item, ReplyByte):
            if not item.is_ack:
                self.nacks += 1
            setter = next((w for w in busy if not w.expect_data), None)
            if setter is not None:
                return self._resolve(setter, item)
            getter = next(iter(busy), None)
            if getter is None:
                return None
            if item.is_ack and self._late:  # perhaps the late ACK of an earlier setter
                getter.unexpected = getter.unexpected or 'ACK'
                return None
            return self._resolve(getter, item)
        if is_greeting(item):
            self.greetings += 1
            return None
        key = (item.opcode, item.axis)
        for waiting in busy:  # the getter that asked, else a setter with that opcode
            if waiting.key == key and waiting.expect_data:
                self._trusted.add(key)
                return self._resolve(waiting, item)
        for waiting in busy:
            if waiting.key == key:
                return self._resolve(waiting, item)
        if len(busy) == 1:  # alone on the link: name what it got if nothing else comes
            busy[0].unexpected = busy[0].unexpected or (
                f'data of opcode 0x{item.opcode:04X} (axis {item.axis})')
        return None

    @staticmethod
    def _resolve(waiting: Waiting, item: Item) -> Waiting:
        waiting.answer = item
        waiting.done = True
        return waiting


def frame_key(frame: Frame) -> tuple[int, int]:
    return frame.opcode, frame.axis
