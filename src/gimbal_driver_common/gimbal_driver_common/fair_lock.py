"""A reentrant lock that goes to its waiters in the order they asked (no ROS).

A request/reply client serialises its link with one lock that two threads share: the
device thread's joint poll and the command path. Python's ``threading.RLock`` is not fair:
a thread that releases it and asks again at once (a command stream sending its next
command, each one several request/reply transactions) takes it back before a waiting
thread has even been scheduled. Measured on the Capture client: with commands back to
back (faster than the link takes them: a loaded machine, or 115200 baud serial, where one
two-axis command is about as long as a 100 Hz period), the poll waited up to 778 ms for its
turn, so joint_states stopped while the axes moved, and a ros2_control stack reading them
saw a tracking error of a quarter radian where the device was on track. With
:class:`FairRLock` each waiter gets the lock after the current holder, in turn.
"""

from __future__ import annotations

import threading
from collections import deque


class FairRLock:
    """Reentrant, first come first served: ``release`` hands the lock to the oldest waiter,
    an urgent one (a stop) before every other."""

    def __init__(self) -> None:
        self._mutex = threading.Lock()
        self._owner: int | None = None
        self._count = 0
        self._waiters: deque[tuple[int, threading.Lock]] = deque()
        self._urgent: deque[tuple[int, threading.Lock]] = deque()
        #: the holder took it urgently (it went ahead of the queue: a stop)
        self._held_urgently = False

    def acquire(self, blocking: bool = True, urgent: bool = False) -> bool:
        """Take the lock; ``blocking=False`` returns False at once when another thread
        holds it or waits for it (a waiter is not overtaken). ``urgent``: go ahead of
        every waiter that is not urgent itself (a stop before the queued reads)."""
        me = threading.get_ident()
        with self._mutex:
            if self._owner == me:
                self._count += 1
                return True
            if self._owner is None:
                self._owner, self._count = me, 1
                self._held_urgently = urgent
                return True
            if not blocking:
                return False
            gate = threading.Lock()
            gate.acquire()
            (self._urgent if urgent else self._waiters).append((me, gate))
        gate.acquire()  # released by the holder that hands the lock to this thread
        return True

    def held(self) -> bool:
        """Whether the calling thread holds the lock."""
        with self._mutex:
            return self._owner == threading.get_ident()

    def held_urgently(self) -> bool:
        """Whether the calling thread holds the lock and took it urgently."""
        with self._mutex:
            return self._owner == threading.get_ident() and self._held_urgently

    def waiting(self, urgent: bool = False) -> int:
        """How many threads wait for the lock (``urgent``: the urgent ones only)."""
        with self._mutex:
            return len(self._urgent) + (0 if urgent else len(self._waiters))

    def release(self) -> None:
        with self._mutex:
            if self._owner != threading.get_ident():
                raise RuntimeError('cannot release a FairRLock held by another thread')
            self._count -= 1
            if self._count:
                return
            queue = self._urgent or self._waiters
            if queue:
                self._held_urgently = queue is self._urgent
                self._owner, gate = queue.popleft()
                self._count = 1
                gate.release()
            else:
                self._owner, self._held_urgently = None, False

    def __enter__(self) -> FairRLock:
        self.acquire()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()
