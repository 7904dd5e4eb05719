"""Notice a motion command that the device accepted but does not carry out (no ROS).

A controller whose TCP stack ACKs a position command it ignores (a drive in a mode that
ignores positions, a brake, a mechanical stall, a controller that takes the target in
another command) otherwise looks like a silent success: ``joint_command`` is accepted and
the axis stays where it is. The controller tells a :class:`MotionWatch` what it sent
(:meth:`commanded`, :meth:`jogged`), what it withdrew (:meth:`withdraw`) and each sample
(:meth:`observe`). An axis whose target is further than the goal tolerance from its
position, or which was told to jog, and which has not moved within
``motion_start_timeout`` seconds, is *stalled*: diagnostics show it (WARN, target and
position), it is logged once per axis and episode, and a running goal ends at once with
:meth:`reason`.

A stalled episode ends when the axis moves (or reaches its target) or when a new motion
command for that axis is accepted, not on a stop: the stop that ends the goal it aborted
would otherwise clear the WARN before the next diagnostics publish, and nobody would see
it (docs/interface.md). A stop (or a superseding command of other axes) ends an episode
that has not stalled yet, so a stopped axis is never reported. A command stream to an
axis that still ignores it is one episode (the same command again does not restart it).

What counts as motion: a position that changed by more than :data:`MOTION_EPSILON` since
the command, and nothing else. A "moving" bit or a speed is not trusted here: some
adapters derive the bit from what was commanded (U-Camera), some devices report the
commanded speed, and a drive that pushes against a brake or a stall reports itself busy
while the axis stays where it is. A slow axis moves that far quickly (at 0.01 rad/s^2 it
takes 0.45 s from rest), so it is not reported; a position that jitters by more than that
hides a stall instead of inventing one. Motion the device runs by itself (its own scans,
playback, homing) is never commanded here and so never watched.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from gimbal_driver_common.config import Logger
from gimbal_driver_common.device import JointSample

#: a joint that moved further than this since its command has started (rad or m)
MOTION_EPSILON = 1e-3


@dataclass
class Episode:
    """One unmet command of one axis: from its first unmet command until it moves."""

    target: float | None      # None: a jog (any motion meets it)
    velocity: float           # the jog velocity (0 for a position target)
    since: float              # monotonic time of the first unmet command
    start: float | None       # the position when it was commanded (None: not known yet)
    position: float = math.nan
    stalled: bool = False
    #: stopped or superseded after it stalled: still shown, no longer waited for (a goal
    #: does not end on it, it does not go on as a stream)
    withdrawn: bool = False

    def describe(self, joint: str, timeout: float) -> str:
        what = (f'target {self.target:.4f}' if self.target is not None
                else f'jog {self.velocity:+.4f}/s')
        return (f'{joint}: commanded but not moving ({what}, position {self.position:.4f}, '
                f'no motion for {timeout:g} s)')


class MotionWatch:
    """Thread-safe: the command thread, the callback and the device thread all feed it."""

    def __init__(self, timeout: Callable[[], float], tolerance: Callable[[], float],
                 log: Logger) -> None:
        self._timeout = timeout
        self._tolerance = tolerance
        self._log = log
        self._lock = threading.Lock()
        self._episodes: dict[str, Episode] = {}
        #: joints whose jog has shown motion, with its direction: the same jog sent again
        #: (a controller streams it to feed the dead-man watchdog) is not a new episode, so
        #: an axis that jogged into its limit and rests there is not reported
        self._running_jogs: dict[str, float] = {}
        self._latest: JointSample | None = None

    # ------------------------------------------------------------ commands
    def commanded(self, targets: dict[str, float]) -> None:
        """Position targets were sent. A joint already waiting keeps the time of its first
        unmet command (a command stream to an axis that ignores it is still reported)."""
        with self._lock:
            for joint, target in targets.items():
                self._running_jogs.pop(joint, None)
                self._start(joint, target, 0.0)

    def jogged(self, velocities: dict[str, float]) -> None:
        """Jog velocities were sent; a zero velocity is a stop (withdraws the joint)."""
        with self._lock:
            for joint, velocity in velocities.items():
                direction = math.copysign(1.0, velocity)
                if velocity == 0.0:
                    self._withdraw(joint)
                elif self._running_jogs.get(joint) != direction:
                    self._running_jogs.pop(joint, None)
                    self._start(joint, None, velocity)

    def withdraw(self, joints: Iterable[str] | None = None) -> None:
        """The commands were stopped or superseded (None: every joint). An episode that
        has not stalled ends; a stalled one stays shown until the axis moves or a new
        command for it is accepted."""
        with self._lock:
            for joint in list(self._episodes) if joints is None else joints:
                self._withdraw(joint)
            if joints is None:
                self._running_jogs.clear()

    def _withdraw(self, joint: str) -> None:
        self._running_jogs.pop(joint, None)
        episode = self._episodes.get(joint)
        if episode is None:
            return
        if episode.stalled:
            episode.withdrawn = True
        else:
            del self._episodes[joint]

    def _start(self, joint: str, target: float | None, velocity: float) -> None:
        position = self._position(joint)
        episode = self._episodes.get(joint)
        if episode is None or episode.withdrawn or \
                (episode.target is None) != (target is None):
            episode = Episode(target, velocity, time.monotonic(), position)
            self._episodes[joint] = episode
        episode.target, episode.velocity = target, velocity
        if episode.start is None:
            episode.start = position
        if position is not None:
            episode.position = position
        if target is not None and position is not None and \
                abs(position - target) <= self._tolerance():
            self._episodes.pop(joint, None)   # already there: nothing to show

    def _position(self, joint: str) -> float | None:
        sample = self._latest
        value = sample.positions.get(joint) if sample else None
        return float(value) if value is not None and math.isfinite(value) else None

    # ------------------------------------------------------------- samples
    def observe(self, sample: JointSample) -> None:
        """A new sample: episodes end when the joint moves or reaches its target; those
        older than the timeout become stalled (logged once)."""
        newly: list[str] = []
        with self._lock:
            self._latest = sample
            if not self._episodes:
                return
            now, timeout, tolerance = time.monotonic(), self._timeout(), self._tolerance()
            for joint, episode in list(self._episodes.items()):
                position = sample.positions.get(joint)
                if position is None or not math.isfinite(position):
                    continue
                episode.position = position
                if episode.start is None:
                    episode.start = position
                reached = episode.target is not None and abs(position - episode.target) \
                    <= tolerance
                moved = abs(position - episode.start) > MOTION_EPSILON
                if reached or moved:
                    del self._episodes[joint]
                    if moved and episode.target is None and not episode.withdrawn:
                        self._running_jogs[joint] = math.copysign(1.0, episode.velocity)
                elif timeout > 0 and now - episode.since >= timeout and not episode.stalled:
                    episode.stalled = True
                    newly.append(episode.describe(joint, timeout))
        for message in newly:
            self._log.warning(f'{message}: the device accepted the command but the axis '
                              'does not move (drive off or in another mode, brake, stall?)')

    # ------------------------------------------------------------- reading
    def stalled(self) -> dict[str, Episode]:
        """The stalled joints now, withdrawn ones included (what diagnostics show; a copy)."""
        with self._lock:
            return {j: Episode(**vars(e)) for j, e in self._episodes.items() if e.stalled}

    def reason(self, joints: Iterable[str]) -> str | None:
        """Why a goal on ``joints`` cannot end well, or None (only commands still waited
        for: a withdrawn episode is shown, not waited for)."""
        stalled = {j: e for j, e in self.stalled().items() if not e.withdrawn}
        found = [stalled[j].describe(j, self._timeout()) for j in joints if j in stalled]
        return '; '.join(found) if found else None
