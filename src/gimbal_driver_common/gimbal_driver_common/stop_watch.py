"""Confirm every stop by the axis: resend it until the axis is at rest (no ROS).

"Stopped" used to mean the bytes were written (or the answers came). A device can drop a
stop (a CAN frame it missed, a corrupted serial packet, a controller busy with something
else) and the axis runs on. The controller tells a :class:`StopWatch` each stop it sends
(:meth:`stopped`), each new motion command (:meth:`superseded`) and each joint sample
(:meth:`observe`, with the time its read began). Each stopped axis has an *episode* until
a sample read after the stop shows it at rest (the one "moving" rule,
``controller.is_moving``, on a known state: a NaN speed without the device's bit is no
rest). An axis still moving when its deceleration time has passed
(its speed over ``stop_deceleration``, plus ``stop_margin``) is *unconfirmed*: it is
logged once per episode, diagnostics read ERROR for it, and :meth:`due` hands it back to
the controller to send the whole stop again, at most once per :data:`RESEND_PERIOD_S`,
for as long as it moves. The watch never gives up: only rest or a newer motion command
ends an episode.

:meth:`wait` lets ``~/stop`` answer the truth: it blocks, woken by samples (never by a
polling sleep), until the axes are at rest or their deceleration time plus the margin has
passed, and returns the axes still moving: an axis whose stop a newer motion command
ended while it waited is among them (it moves by that command; found in a loaded run: a
jog published just before ``~/stop`` reached the node just after it, and ``~/stop``
answered success while the jog ran).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from gimbal_driver_common.config import Logger
from gimbal_driver_common.device import JointSample

#: s: the shortest time between two resends of the stop to one axis
RESEND_PERIOD_S = 0.25
#: ``moving`` rule the controller uses (injected: the controller owns is_moving)
MovingRule = Callable[[JointSample | None, str], bool]


@dataclass
class StopEpisode:
    """One stop of one axis, from the first stop sent until a sample shows it at rest."""

    since: float                 # when the first stop of the episode was sent
    due: float                   # when it must be at rest (after a resend: the next check)
    sent: int = 1                # stops sent in this episode
    speed: float = math.nan      # |velocity| in the last sample (nan: not known)
    unconfirmed: bool = False    # past due and still moving: ERROR, logged once

    def describe(self) -> str:
        speed = f'{self.speed:.3f}' if math.isfinite(self.speed) else '?'
        times = 'once' if self.sent == 1 else f'{self.sent} times'
        return f'stop not confirmed: still moving at {speed} rad/s, stop sent {times}'


class StopWatch:
    """Thread-safe: stops come from any thread, samples from the device thread."""

    def __init__(self, deceleration: Callable[[], float], margin: Callable[[], float],
                 moving: MovingRule, log: Logger,
                 clock: Callable[[], float] = time.monotonic,
                 resend_period: float = RESEND_PERIOD_S) -> None:
        self._deceleration = deceleration
        self._margin = margin
        self._moving = moving
        self._log = log
        self._clock = clock
        self.resend_period = resend_period
        self._changed = threading.Condition()
        self._episodes: dict[str, StopEpisode] = {}
        self._latest: JointSample | None = None
        #: per joint, how many of its stop episodes a newer motion command ended
        self._overridden: dict[str, int] = {}

    # ------------------------------------------------------------ stops
    def settle_time(self, *joints: str) -> float:
        """s the slowest of these axes needs to rest from its last known speed, plus the
        margin."""
        deceleration = self._deceleration()
        braking = [speed / deceleration for speed in
                   (self._speed(self._latest, joint) for joint in joints)
                   if math.isfinite(speed) and deceleration > 0]
        return max(braking, default=0.0) + max(self._margin(), 0.0)

    def stopped(self, joints: Iterable[str]) -> None:
        """A stop of ``joints`` is being sent: an episode starts (or counts one more)."""
        now = self._clock()
        with self._changed:
            for joint in joints:
                episode = self._episodes.get(joint)
                if episode is None:
                    self._episodes[joint] = StopEpisode(
                        now, now + self.settle_time(joint), speed=self._speed(self._latest,
                                                                              joint))
                else:
                    episode.sent += 1
                    episode.due = max(episode.due, now + self.resend_period)

    def superseded(self, joints: Iterable[str] | None = None) -> None:
        """A new motion command owns these joints (None: all): not waited for any more.
        On the joint_command path: one look, no lock, while no stop waits (a stop sent
        meanwhile is newer than this command and stays watched)."""
        if not self._episodes:
            return
        with self._changed:
            for joint in list(self._episodes) if joints is None else joints:
                if self._episodes.pop(joint, None) is not None:
                    self._overridden[joint] = self._overridden.get(joint, 0) + 1
            self._changed.notify_all()

    # ----------------------------------------------------------- samples
    def observe(self, sample: JointSample, read_at: float) -> None:
        """A sample whose read began at ``read_at`` (the watch's clock): an axis it shows
        at rest, read after that axis's stop, is confirmed. Per sample while no stop
        waits: one assignment and one look, no lock (a stop sent meanwhile is confirmed by
        the next sample, which is read after it)."""
        self._latest = sample
        if not self._episodes:
            return
        with self._changed:
            for joint, episode in list(self._episodes.items()):
                speed = self._speed(sample, joint)
                if math.isfinite(speed):
                    episode.speed = speed
                if (read_at >= episode.since and self._known(sample, joint)
                        and not self._moving(sample, joint)):
                    del self._episodes[joint]
                    if episode.unconfirmed:
                        self._log.info(f'{joint}: at rest after the stop was sent '
                                       f'{episode.sent} times')
            self._changed.notify_all()

    def due(self) -> list[str]:
        """The axes to send the whole stop again now (still moving past their time);
        the first time per episode it is logged. The caller sends it and calls
        :meth:`stopped`."""
        if not self._episodes:  # the housekeeping thread's usual look: no lock
            return []
        now = self._clock()
        newly: list[tuple[str, StopEpisode]] = []
        found: list[str] = []
        with self._changed:
            for joint, episode in self._episodes.items():
                if now < episode.due:
                    continue
                found.append(joint)
                episode.due = now + self.resend_period
                if not episode.unconfirmed:
                    episode.unconfirmed = True
                    newly.append((joint, StopEpisode(**vars(episode))))
        for joint, episode in newly:
            self._log.error(f'{joint}: {episode.describe()} (sending it again until the '
                            'axis is at rest)')
        return sorted(found)

    # ------------------------------------------------------------ reading
    def waiting(self) -> bool:
        """Some stop waits for its axis (the housekeeping thread looks often only then)."""
        return bool(self._episodes)

    def at_rest(self, joint: str) -> bool:
        """No stop of ``joint`` waits for confirmation."""
        with self._changed:
            return joint not in self._episodes

    def unconfirmed(self) -> dict[str, StopEpisode]:
        """The axes whose stop is overdue (what diagnostics show as ERROR; copies)."""
        with self._changed:
            return {j: StopEpisode(**vars(e)) for j, e in self._episodes.items()
                    if e.unconfirmed}

    def episodes(self) -> dict[str, StopEpisode]:
        """Every stop still waiting for its axis (copies)."""
        with self._changed:
            return {j: StopEpisode(**vars(e)) for j, e in self._episodes.items()}

    def still_moving(self, joints: Sequence[str]) -> str:
        """"stop not confirmed: pan still moving at 0.300 rad/s, stop sent twice; tilt
        moved by a newer motion command" """
        episodes = self.episodes()
        parts = [f'{j} {episodes[j].describe().removeprefix("stop not confirmed: ")}'
                 if j in episodes else f'{j} moved by a newer motion command'
                 for j in joints]
        return 'stop not confirmed: ' + '; '.join(parts)

    def wait(self, joints: Sequence[str], timeout: float,
             wait: Callable[[threading.Condition, float], object] | None = None) -> list[str]:
        """Block until ``joints`` are at rest or ``timeout`` s passed; the ones still
        moving. Woken by each sample (``wait`` replaces the condition's own wait in tests
        on an injected clock)."""
        deadline = self._clock() + timeout
        with self._changed:
            overridden = {j: self._overridden.get(j, 0) for j in joints}
            while True:
                moving = [j for j in joints if j in self._episodes
                          or self._overridden.get(j, 0) != overridden[j]]
                left = deadline - self._clock()
                if not moving or left <= 0 or all(j not in self._episodes for j in moving):
                    return moving
                if wait is None:
                    self._changed.wait(left)
                else:
                    wait(self._changed, left)

    @staticmethod
    def _known(sample: JointSample, joint: str) -> bool:
        """The sample says whether ``joint`` moves: the device's own bit, or a speed that
        is not NaN. A NaN speed (the device's report of it stale or missing: the turret)
        is no rest; the moving rule alone reads it as below the threshold. A device that
        reports no speed at all (no entry) is read by the moving rule, as before."""
        if joint in sample.moving:
            return True
        value = sample.velocities.get(joint)
        return value is None or not math.isnan(value)

    @staticmethod
    def _speed(sample: JointSample | None, joint: str) -> float:
        if sample is None:
            return math.nan
        value = sample.velocities.get(joint)
        return abs(float(value)) if value is not None and math.isfinite(value) else math.nan
