"""The request faults of every simulator: ``mute <request>``, ``delay <request> <seconds>``
and ``ignore <request> <seconds>``.

A device in the field can leave one kind of request unanswered (an IMU not fitted, firmware
that drops a request it cannot serve, a sensor board that hangs) or answer it late while it
answers everything else at once. :class:`RequestFaults` holds which requests a simulator
treats so; the control verbs of :mod:`gimbal_driver_common.sim_control` set it and each
simulator consults it where it decides how to answer a request:

* muted: the request is read off the link and logged as received, then dropped: the device
  does not act on it and never answers it;
* ignored (for a time): the request is received, logged and answered as the device answers
  it (an ACK, an OK line; nothing where the protocol answers nothing) but not acted on:
  a stop or a motion message the device dropped (a controller busy with something else, a
  CAN frame it missed, a corrupted serial packet). It ends by itself after its seconds;
* delayed: the request is executed when it arrives and its reply (data, ACK, NACK, error:
  whatever the device answers) is held in the link's :class:`LateReplies` and written by the
  link's own writer when due, so the replies to other requests go out at once meanwhile and
  no write is torn or interleaved. A held reply is lost with its connection, as a real
  device's is.

Requests are named as each device's protocol names them (a Capture command, a kOS message,
a CANaerospace node service, a UCSP packet, a line-protocol verb).
"""

from __future__ import annotations

import heapq
import itertools
import math
import threading
import time
from collections.abc import Callable, Iterable
from typing import Generic, TypeVar

T = TypeVar('T')


class RequestFaults:
    """Which requests go unanswered (muted), are answered late (delayed) or answered and
    not acted on (ignored, for a time); thread-safe:
    the control console writes, the link threads read."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._muted: set[str] = set()
        self._delays: dict[str, float] = {}
        #: name -> until when (the clock's time) it is taken and not acted on
        self._ignored: dict[str, float] = {}

    def mute(self, name: str, muted: bool = True) -> None:
        """Never answer ``name`` (``muted=False``: answer it again); a mute replaces a delay."""
        with self._lock:
            self._delays.pop(name, None)
            if muted:
                self._muted.add(name)
            else:
                self._muted.discard(name)

    def delay(self, name: str, seconds: float) -> None:
        """Answer ``name`` ``seconds`` late (0: at once); a delay replaces a mute."""
        if not (math.isfinite(seconds) and seconds >= 0.0):
            raise ValueError(f'delay {seconds!r}: not a finite number of seconds >= 0')
        with self._lock:
            self._muted.discard(name)
            if seconds > 0.0:
                self._delays[name] = seconds
            else:
                self._delays.pop(name, None)

    def ignore(self, name: str, seconds: float) -> None:
        """Take ``name`` and answer it, but do not act on it, for ``seconds`` (0: act again)."""
        if not (math.isfinite(seconds) and seconds >= 0.0):
            raise ValueError(f'ignore {seconds!r}: not a finite number of seconds >= 0')
        with self._lock:
            if seconds > 0.0:
                self._ignored[name] = self._clock() + seconds
            else:
                self._ignored.pop(name, None)

    def ignored(self, name: str) -> bool:
        """True while ``name`` is to be answered but not acted on."""
        with self._lock:
            until = self._ignored.get(name)
            if until is None:
                return False
            if self._clock() < until:
                return True
            del self._ignored[name]
            return False

    def clear(self) -> None:
        with self._lock:
            self._muted.clear()
            self._delays.clear()
            self._ignored.clear()

    def muted(self, name: str) -> bool:
        with self._lock:
            return name in self._muted

    def delay_of(self, name: str) -> float:
        """Seconds to hold the reply to ``name`` (0.0: answer at once)."""
        with self._lock:
            return self._delays.get(name, 0.0)

    def snapshot(self) -> dict[str, object]:
        """For the ``state`` answer: ``muted`` (names), ``delayed`` (name -> seconds) and
        ``ignored`` (name -> seconds left)."""
        with self._lock:
            now = self._clock()
            ignored = {n: round(until - now, 3) for n, until in sorted(self._ignored.items())
                       if until > now}
            return {'muted': sorted(self._muted), 'delayed': dict(sorted(self._delays.items())),
                    'ignored': ignored}


class LateReplies(Generic[T]):
    """Replies held back by ``delay``, released in the order they fall due (equal times in
    the order held). The link's writer takes them with :meth:`due` from the loop that writes
    its other replies, so a late reply never splits another one."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._heap: list[tuple[float, int, T]] = []
        self._order = itertools.count()

    def hold(self, replies: Iterable[T], seconds: float) -> None:
        """Hold ``replies`` (one request's answer, sent together) for ``seconds``."""
        due = self._clock() + seconds
        with self._lock:
            for reply in replies:
                heapq.heappush(self._heap, (due, next(self._order), reply))

    def due(self, now: float | None = None) -> list[T]:
        """The held replies due by ``now``, in order; they are no longer held."""
        now = self._clock() if now is None else now
        out: list[T] = []
        with self._lock:
            while self._heap and self._heap[0][0] <= now:
                out.append(heapq.heappop(self._heap)[2])
        return out

    def clear(self) -> None:
        """Drop every held reply (``clear``: a shared bus's late answer must not answer the
        next node's request of the same name)."""
        with self._lock:
            self._heap.clear()

    def __len__(self) -> int:
        with self._lock:
            return len(self._heap)


def resolve_request(name: str, known: Iterable[str]) -> str:
    """The known request spelled ``name`` (exactly, else the one that matches ignoring case);
    LookupError naming the known ones otherwise, so a user can discover them."""
    names = list(known)
    if name in names:
        return name
    folded = [known_name for known_name in names if known_name.lower() == name.lower()]
    if len(folded) == 1:
        return folded[0]
    raise LookupError(f'unknown request {name!r}; known: {", ".join(sorted(names))}')
