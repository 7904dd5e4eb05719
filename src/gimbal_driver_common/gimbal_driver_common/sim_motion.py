"""The axis motion model every simulator shares (no ROS): a trapezoidal velocity profile.

One :class:`AxisMotion` is one motor axis in the simulator's own units (degrees,
radians, rotations: the device's units stay at the simulator's edge). It moves toward
a position target or at a jog velocity, accelerating at ``acceleration`` and braking
at ``deceleration``, never faster than ``max_speed`` (or the slower ``speed`` of the
current move), and stops at ``min_position``/``max_position``. Time is injected: the
owner calls :meth:`AxisMotion.step` with the elapsed time, so tests drive it exactly.

State is plain attributes so a device model can act on it directly, as firmware does:
``target`` (None = no position move), ``jog_velocity`` (None = not jogging; 0.0 =
jogging at zero, i.e. braking to rest), ``speed`` (the move's speed limit; None =
``max_speed``). Without a target or a jog the axis brakes to rest at ``deceleration``
(a controlled stop); :meth:`stop` with ``immediate=True`` halts at once (an emergency
stop, a tripped drive). A subclass may override :meth:`goal` (e.g. a homing run toward
a fixed point) and :meth:`on_arrival` (what a reached target means to the device).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Integration step: :meth:`AxisMotion.step` splits longer intervals into steps this long
#: so that lazily integrated models (advanced only when a request arrives) keep the shape
#: of the profile.
MAX_SUBSTEP_S = 0.005
#: Positions closer than this to the target count as arrived (units of the axis).
ARRIVAL_TOLERANCE = 1e-9


@dataclass
class AxisMotion:
    """One axis: trapezoidal profile toward ``target`` or at ``jog_velocity``, with limits."""

    max_speed: float = math.inf
    acceleration: float = math.inf
    deceleration: float | None = None  # None: the same as acceleration
    min_position: float | None = None
    max_position: float | None = None
    position: float = 0.0
    velocity: float = 0.0
    target: float | None = None
    jog_velocity: float | None = None
    speed: float | None = None  # speed limit of the current move; None: max_speed
    #: the fault ``ignore_motion``: the protocol still ACKs moves and jogs, but an axis at
    #: rest drops them at its next step (a drive in a mode that ignores positions, a brake,
    #: a stall). Motion already under way goes on; device-run goals (:meth:`goal`) too.
    ignore_commands = False

    # ---------------------------------------------------------------- commands
    def move_to(self, target: float, speed: float | None = None) -> None:
        """Start a position move (the target is clamped to the limits)."""
        self.target = self.clamp(target)
        self.jog_velocity = None
        self.speed = speed

    def jog(self, velocity: float) -> None:
        """Run at ``velocity`` (clamped to ``max_speed``) until stopped or at a limit."""
        self.target = None
        self.jog_velocity = max(-self.max_speed, min(self.max_speed, velocity))

    def stop(self, immediate: bool = False) -> None:
        """End the move or jog: brake to rest at ``deceleration``, or halt at once."""
        self.target = None
        self.jog_velocity = None
        if immediate:
            self.velocity = 0.0

    def set_limits(self, low: float | None, high: float | None) -> None:
        self.min_position, self.max_position = low, high

    # ----------------------------------------------------------------- queries
    @property
    def mode(self) -> str:
        """``position``, ``jog``, ``stopping`` (braking to rest) or ``idle``."""
        if self.target is not None:
            return 'position'
        if self.jog_velocity is not None:
            return 'jog'
        return 'stopping' if self.velocity != 0.0 else 'idle'

    @property
    def move_speed(self) -> float:
        """The speed limit a position move runs at now: the move's ``speed`` within
        ``max_speed``."""
        return self.max_speed if self.speed is None else min(abs(self.speed), self.max_speed)

    @property
    def moving(self) -> bool:
        """The axis turns, or has a move or a non-zero jog still to run."""
        return (self.velocity != 0.0 or self.target is not None
                or bool(self.jog_velocity))

    @property
    def limit_reached(self) -> int:
        """-1 resting on the lower limit, +1 on the upper one, 0 inside the range."""
        if self.min_position is not None and self.position <= self.min_position:
            return -1
        if self.max_position is not None and self.position >= self.max_position:
            return 1
        return 0

    def clamp(self, position: float) -> float:
        if self.min_position is not None:
            position = max(position, self.min_position)
        if self.max_position is not None:
            position = min(position, self.max_position)
        return position

    def snapshot(self) -> dict[str, object]:
        """The axis as JSON-ready values (the simulators' ``state`` answer)."""
        return {'position': self.position, 'velocity': self.velocity, 'target': self.target,
                'mode': self.mode, 'moving': self.moving}

    # ------------------------------------------------------------ overridables
    def goal(self) -> tuple[float | None, float | None]:
        """(position target or None, speed limit or None) the profile runs toward now."""
        return self.target, self.speed

    def on_arrival(self) -> None:
        """The target was reached exactly (position == target, velocity 0)."""
        self.target = None

    # -------------------------------------------------------------------- time
    def step(self, dt: float) -> bool:
        """Advance ``dt`` seconds; True when the axis came to rest during it (arrived at its
        target, braked to a stop or ran into a limit)."""
        if self.ignore_commands and self.velocity == 0.0:
            self.target = None  # taken (the protocol ACKed it) and forgotten
            self.jog_velocity = None if self.jog_velocity is None else 0.0
        if self.velocity == 0.0 and not self.jog_velocity and self.goal()[0] is None:
            return False  # at rest with nothing to do (the common case: keep it cheap)
        came_to_rest = False
        while dt > 0.0:
            sub = min(dt, MAX_SUBSTEP_S)
            dt -= sub
            was_moving = self.moving
            self._integrate(sub)
            came_to_rest = came_to_rest or (was_moving and not self.moving)
        return came_to_rest

    def _deceleration(self) -> float:
        return self.acceleration if self.deceleration is None else self.deceleration

    def _braking_speed(self, distance: float, dt: float) -> float:
        """The highest speed from which braking by ``deceleration * dt`` per step stops
        within ``distance`` (the discrete form of sqrt(2 a d), so the axis lands on the
        target without overshoot and without exceeding the deceleration)."""
        deceleration = self._deceleration()
        if math.isinf(deceleration):
            return math.inf
        step_speed = max(deceleration, 1e-9) * dt  # a device may be set to 0: crawl, not crash
        steps = (-1.0 + math.sqrt(1.0 + 8.0 * distance / (step_speed * dt))) / 2.0
        return steps * step_speed

    def _approach(self, desired: float, dt: float) -> None:
        """Change the velocity toward ``desired`` within the acceleration limits."""
        speeding_up = abs(desired) > abs(self.velocity) and desired * self.velocity >= 0.0
        rate = self.acceleration if speeding_up else self._deceleration()
        change = desired - self.velocity
        limit = rate * dt
        self.velocity = desired if abs(change) <= limit else self.velocity + math.copysign(
            limit, change)

    def _integrate(self, dt: float) -> None:
        target, speed = self.goal()
        cap = self.max_speed if speed is None else min(abs(speed), self.max_speed)
        if target is not None:
            target = self.clamp(target)
            error = target - self.position
            if abs(error) <= ARRIVAL_TOLERANCE and abs(self.velocity) <= self._deceleration() * dt:
                self.position, self.velocity = target, 0.0
                self.on_arrival()
                return
            if cap <= 0.0:
                self.velocity = 0.0  # a move at speed 0 holds the axis where it is
                return
            desired = math.copysign(min(cap, self._braking_speed(abs(error), dt)), error)
            self._approach(desired, dt)
            advance = self.velocity * dt
            if advance * error > 0 and abs(advance) >= abs(error):
                self.position, self.velocity = target, 0.0  # arrives within this step
                self.on_arrival()
                return
            self.position += advance
        else:
            desired = 0.0 if self.jog_velocity is None else max(-cap, min(cap, self.jog_velocity))
            self._approach(desired, dt)
            self.position += self.velocity * dt
        self._stop_at_limits()

    def _stop_at_limits(self) -> None:
        """A limit stops the axis there: the jog ends, a target beyond it is dropped."""
        clamped = self.clamp(self.position)
        if clamped == self.position:
            return
        self.position, self.velocity = clamped, 0.0
        self.jog_velocity = None
        if self.target is not None and self.clamp(self.target) == clamped:
            self.target = None
