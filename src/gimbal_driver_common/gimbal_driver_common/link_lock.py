"""The one lock of a request/reply device link, owned by the core (no ROS).

A device whose link answers every request in turn (Capture's ACK bytes, the virtual
gimbal's reply lines) has one exchange on the link at a time: whoever writes a request
reads its answer before anyone else writes. Its users are several threads: the joint
poll, the sensor and service calls, the command path. They all hold this lock for a whole
exchange. The :class:`~gimbal_driver_common.device.Device` base makes one per device
(``Device.link_lock``); the adapter hands it to its client, which takes it around every
exchange, and the command path (:mod:`gimbal_driver_common.command_path`) uses the same
lock for its sends.

One write goes out without its exchange: a joint_command posted from the callback, whose
answers nobody waits for then (the callback never waits for a device reply). Before any
other user writes, those answers must be read, or they would answer the next request.
So the lock settles the posted write itself: every hold runs ``before_use`` (the command
path's settle: nothing to do unless a write is posted) before the holder's own exchange.
The callback's one non-blocking try (:meth:`LinkLock.try_hold`) does not settle: it posts
only when nothing is posted.

Fair (:class:`~gimbal_driver_common.fair_lock.FairRLock`): a command stream sent back to
back does not starve the joint poll. A stop (``~/stop``, the dead-man stop, a cancelled
goal's stop) holds it with :meth:`LinkLock.urgent`: ahead of every queued exchange, and it
does not wait for the one in flight either when the device can cut that short: the lock
first calls ``preempt`` (Capture: the answer book ends the exchange in flight at once, its
waiter fails "preempted by a stop", no request of the holder goes out before the stop, and
a late answer is the stop's to count by rule), then ``preempt_done`` when the stop's hold
ends. The core's defaults do nothing: a device that sets neither has a stop wait for the
exchange in flight, as a write-only device never has one.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator

from gimbal_driver_common.fair_lock import FairRLock


class LinkLock:
    """Reentrant and fair; every blocking hold settles a posted write first."""

    def __init__(self) -> None:
        self._lock = FairRLock()
        #: run by every blocking hold, before the holder's exchange; the command path sets
        #: it to settle a posted write (it must take the write off before reading its
        #: answers: the reading holds this lock again)
        self.before_use: Callable[[], None] = lambda: None
        #: run by :meth:`urgent` before it waits for the lock: the device ends the exchange
        #: in flight now (its waiter fails) so that the holder gives the lock up at once;
        #: ``preempt_done`` runs when that stop's hold ends (set together, by the client)
        self.preempt: Callable[[], None] = lambda: None
        self.preempt_done: Callable[[], None] = lambda: None

    def __enter__(self) -> LinkLock:
        self.hold()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._lock.release()

    def hold(self, urgent: bool = False) -> None:
        """Take the lock (``urgent``: ahead of every queued exchange that is not urgent,
        for a stop) and settle a posted write; give it back with :meth:`release`."""
        self._lock.acquire(urgent=urgent)
        try:
            self.before_use()
        except BaseException:
            self._lock.release()
            raise

    @contextlib.contextmanager
    def urgent(self) -> Iterator[LinkLock]:
        """``with lock.urgent():`` a stop's exchange: the one in flight preempted
        (``preempt``), then ahead of every queued exchange."""
        self.preempt()
        try:
            self.hold(urgent=True)
            try:
                yield self
            finally:
                self._lock.release()
        finally:
            self.preempt_done()

    def held(self) -> bool:
        """Whether the calling thread holds the lock (a request it writes is one a stop
        would wait for: the client lets the stop preempt it)."""
        return self._lock.held()

    def held_urgently(self) -> bool:
        """Whether the calling thread holds the lock for a stop (:meth:`urgent`): a
        request/reply client lets such a request out while reads wait for answers."""
        return self._lock.held_urgently()

    def waiting(self, urgent: bool = False) -> int:
        """How many exchanges wait for the link (``urgent``: the stops only)."""
        return self._lock.waiting(urgent)

    def try_hold(self) -> bool:
        """Take the lock if nobody holds or waits for it, without settling anything (the
        joint_command callback's one try); give it back with :meth:`release`."""
        return self._lock.acquire(blocking=False)

    def release(self) -> None:
        """Give back a hold taken with :meth:`try_hold`."""
        self._lock.release()
