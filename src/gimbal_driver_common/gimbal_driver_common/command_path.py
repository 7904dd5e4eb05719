"""The one command path: how every driver sends a joint_command (no ROS).

A joint_command is queued newest-per-joint. The caller's thread (the joint_command
callback) then offers it to the device once, when no other send holds the link:
``Device.post`` writes what needs no answer-wait and says how many answers to settle
(0 for a write-only device: the turret's CAN frames, Kessler's kOS messages, U-Camera's
packets). Everything else, and the answers of a post, is the command thread's: it
settles a posted write (``Device.settle``), sends again the moves whose answers were
lost unless a stop or a newer move for the joint went out since, and sends the queue
with ``Device.move`` and ``Device.jog``. Any other send (move_to, a stop) settles a
posted write first, so nothing stale follows it; a stop preempts the exchange in flight
where the device can (``LinkLock.preempt``) and under its hold sends nothing again before
itself. The caller never waits for a device answer nor behind another send: the one
non-blocking try is here, on the device's link lock (:attr:`CommandPath.link_lock`, the
:class:`~gimbal_driver_common.link_lock.LinkLock` the ``Device`` base owns). A
request/reply client takes that same lock around each exchange (its poll, sensors and
services too), and the lock settles a posted write before anyone else uses the link
(``before_use``): the adapter says what it wrote and how many answers to expect
(:class:`~gimbal_driver_common.device.PostedWrite`), and holds no lock of its own.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Sequence

from gimbal_driver_common.device import Device, Moves, PostedWrite
from gimbal_driver_common.errors import DeviceRefused, GimbalError, Preempted, device_boundary
from gimbal_driver_common.rejections import CommandRejections

__all__ = ['CommandPath', 'yield_core']

#: joint -> ('move', target, speed) or ('jog', velocity, None)
Pending = dict[str, tuple[str, float, float | None]]


class StopLedger:
    """The stops sent, numbered, so that a send a stop preempted (:class:`Preempted`)
    can tell whether a stop since it began covered its joints: then it stays undone;
    else (the dead-man stop of another joint) it goes out again after the stop."""

    #: stops remembered; a send that began before the oldest counts as stopped
    KEPT = 64

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._count = 0
        self._stops: list[tuple[int, frozenset[str] | None]] = []

    def mark(self) -> int:
        """Where a send begins: :meth:`stopped_since` looks at the stops after it."""
        return self._count

    def record(self, joints: Sequence[str] | None) -> None:
        with self._lock:
            self._count += 1
            self._stops.append((self._count, None if joints is None else frozenset(joints)))
            del self._stops[:-self.KEPT]

    def stopped_since(self, mark: int) -> frozenset[str] | None:
        """The joints stopped after ``mark`` (None: every joint)."""
        with self._lock:
            if self._stops and self._stops[0][0] > mark + 1:
                return None  # older than what is kept: take it as stopped
            covered: set[str] = set()
            for number, joints in self._stops:
                if number > mark:
                    if joints is None:
                        return None
                    covered |= joints
            return frozenset(covered)


def yield_core() -> None:
    """Give this thread's core away once, right after the joint_command callback wrote a
    command.

    What happens next in the callback's thread is rclpy's executor bookkeeping (finishing
    the task, rebuilding its wait set in Python: about 0.3 ms), none of it urgent. The
    process at the other end of the bytes (a simulator on this machine, a serial or TCP
    bridge) was just woken and needs a core to act on them; on 2 cores it waited for that
    bookkeeping. Measured (``make bench``, Capture alone, 2 runs each, 2-core machine): p50
    publish -> command bytes at the simulator, 50 / 100 Hz, 1.12-1.21 / 0.79-1.00 ms
    without, 0.84-0.95 / 0.67-0.69 ms with (ratio to the bare rclpy reference 1.31-1.57
    -> 1.08-1.28). One system call; it returns at once when nothing else waits for a core.
    """
    os.sched_yield()


class CommandPath:
    """Queue, post, settle and resend joint_commands for one device (thread-safe).

    ``record_targets`` gets the targets of the moves known to have gone out (the
    controller's ``commanded_targets`` and motion watch), ``record_jogs`` the jog
    velocities that went out. ``refusal`` says why nothing can be sent now (the link is
    down), or None.
    """

    def __init__(self, device: Device, rejections: CommandRejections,
                 record_targets: Callable[[dict[str, float]], None],
                 refusal: Callable[[], str | None],
                 record_jogs: Callable[[dict[str, float]], None] = lambda jogs: None) -> None:
        self.device = device
        self.rejections = rejections
        self._record_targets = record_targets
        self._record_jogs = record_jogs
        self._refusal = refusal
        #: the device's link lock: one exchange on the link at a time, shared with the
        #: device's own requests; its first hold settles what the caller posted
        self.link_lock = device.link_lock
        self.link_lock.before_use = self._settle_posted
        self._queue_lock = threading.Lock()
        self._pending: Pending = {}
        #: a write whose answers nobody has read yet (None: none); a joint leaves its
        #: moves when a newer send for it (a stop, move_to) goes out first
        self._posted: PostedWrite | None = None
        self.ready = threading.Event()
        self._stopping = threading.Event()
        #: the stops sent: a move or jog a stop preempted goes out again after it when
        #: the stop did not cover its joints
        self.stops = StopLedger()

    # ------------------------------------------------------------ the caller
    def submit(self, moves: Moves, jogs: dict[str, float]) -> None:
        """Queue a joint_command (newest per joint wins) and get it out without waiting:
        posted from this thread when the link is free, else by the command thread."""
        with self._queue_lock:
            for joint, (target, speed) in moves.items():
                self._pending[joint] = ('move', target, speed)
            for joint, velocity in jogs.items():
                self._pending[joint] = ('jog', velocity, None)
        if self.link_lock.try_hold():
            try:
                posted = self._post_pending()
            finally:
                self.link_lock.release()
            if posted is not None:
                if posted.replies:
                    self.ready.set()  # the command thread settles the answers
                yield_core()
                return
        self.ready.set()
        # Let the command thread take the GIL now. Otherwise it waits until this
        # (executor) thread blocks again, after rclpy's wait-set rebuild: measured in
        # a loop with 300 us of Python after the set(), hand-off p50 330 -> 50 us.
        time.sleep(0)

    def _post_pending(self) -> PostedWrite | None:
        """Offer the queue to ``device.post`` (caller holds :attr:`lock`); what was
        written, or None with the queue left for the command thread."""
        if self._posted is not None:  # answers of an earlier post still to read
            return None
        with self._queue_lock:
            pending = self._pending
            if not pending or self._refusal() is not None:
                return None
            moves, jogs = _split(pending)
            try:
                with device_boundary():
                    posted = self.device.post(moves, jogs)
            except GimbalError as exc:
                self._pending = {}
                self.rejections.record(exc, sent=True)
                return PostedWrite()
            if posted is None:
                return None
            self._pending = {}
        if posted.jogs:
            self._record_jogs(dict(posted.jogs))
        if posted.replies:
            self._posted = posted
        else:
            self._record_targets({joint: move[0] for joint, move in posted.moves.items()})
        return posted

    # -------------------------------------------------------- other senders
    def send(self, joints: Sequence[str] | None, request: Callable[[], object],
             urgent: bool = False) -> None:
        """Run another send (move_to, a stop) now: the queued commands of ``joints``
        (None: all) are dropped, a posted write is settled first and not sent again for
        them. ``urgent`` (a stop): the exchange in flight preempted where the device can
        (``LinkLock.preempt``), ahead of every queued read. The caller's own refusals
        raise (device_boundary)."""
        self.drop(joints)  # before the lock's settle, which would send them again
        if urgent:
            self.stops.record(joints)
            with self.link_lock.urgent():
                self.drop(joints)  # and what the caller queued meanwhile
                with device_boundary():
                    request()
            return
        mark = self.stops.mark()
        try:
            with self.link_lock:
                self.drop(joints)
                with device_boundary():
                    request()
        except Preempted:
            stopped = self.stops.stopped_since(mark)
            if stopped is None or joints is None or stopped & set(joints):
                raise
            # a stop of other joints went first: this send once more, after it
            with self.link_lock, device_boundary():
                request()

    def drop(self, joints: Sequence[str] | None) -> None:
        """Forget queued commands, and a posted write's moves, for a newer send."""
        with self._queue_lock:
            if joints is None:
                self._pending.clear()
                if self._posted is not None:
                    self._posted.moves.clear()
                return
            for joint in joints:
                self._pending.pop(joint, None)
                if self._posted is not None:
                    self._posted.moves.pop(joint, None)

    # -------------------------------------------------------- command thread
    def run(self) -> None:
        """The command thread: settle what the caller posted, send what it queued."""
        while not self._stopping.is_set():
            self.ready.wait()
            self.ready.clear()
            with self.link_lock:  # settles a posted write first (before_use)
                self._flush_pending()

    def close(self) -> None:
        """End :meth:`run` (the controller joins its thread)."""
        self._stopping.set()
        self.ready.set()

    def reopen(self) -> None:
        self._stopping.clear()

    def _settle_posted(self) -> None:
        """Read a posted write's answers (the lock's ``before_use``: every holder, from any
        thread, runs it before its own exchange); send its moves again when answers
        were lost, unless superseded (a stop, a newer move or a queued one). Under a
        stop's hold they are queued for the command thread instead: nothing waits for
        an answer before the stop goes out."""
        posted, self._posted = self._posted, None
        if posted is None:
            return
        try:
            with device_boundary():
                answered = self.device.settle(posted)
        except GimbalError as exc:
            self.rejections.record(exc, sent=True)
            return
        with self._queue_lock:
            live = {j: m for j, m in posted.moves.items() if j not in self._pending}
            if not answered and live and self.link_lock.held_urgently():
                # a stop's hold writes nothing before the stop: the moves go after it
                for joint, (target, speed) in live.items():
                    self._pending[joint] = ('move', target, speed)
                self.ready.set()
                return
        if not answered and live:
            try:
                with device_boundary():
                    self.device.move(live)
            except GimbalError as exc:
                self.rejections.record(exc, sent=True)
                return
        self._record_targets({joint: move[0] for joint, move in posted.moves.items()})

    def _flush_pending(self) -> None:
        """Send the queued commands, moves first (caller holds :attr:`lock`)."""
        with self._queue_lock:
            pending, self._pending = self._pending, {}
        if not pending:
            return
        refusal = self._refusal()
        if refusal is not None:  # the link dropped after the command was accepted
            self.rejections.record(DeviceRefused(refusal, reason='device not connected'))
            return
        moves, jogs = _split(pending)
        mark = self.stops.mark()
        try:
            with device_boundary():
                if moves:
                    self.device.move(moves)
                if jogs:
                    self.device.jog(jogs)
        except Preempted as exc:
            if not self._requeue_preempted(pending, mark):
                self.rejections.record(exc, sent=True)
            return
        except GimbalError as exc:
            self.rejections.record(exc, sent=True)
            return
        if jogs:
            self._record_jogs(jogs)
        self._record_targets({joint: move[0] for joint, move in moves.items()})


    def _requeue_preempted(self, pending: Pending, mark: int) -> bool:
        """A stop preempted these commands: queue again, for after it, those of joints
        it did not stop and no newer command replaced. True when any was."""
        stopped = self.stops.stopped_since(mark)
        if stopped is None:
            return False
        with self._queue_lock:
            again = {j: c for j, c in pending.items()
                     if j not in stopped and j not in self._pending}
            self._pending.update(again)
        if again:
            self.ready.set()
        return bool(again)


def _split(pending: Pending) -> tuple[Moves, dict[str, float]]:
    moves = {j: (v, s) for j, (kind, v, s) in pending.items() if kind == 'move'}
    jogs = {j: v for j, (kind, v, _) in pending.items() if kind == 'jog'}
    return moves, jogs
