"""The shared simulator axis model: trapezoidal profile, limits, jogs, stops (in-process)."""

from __future__ import annotations

import math

import pytest

from gimbal_driver_common.sim_motion import AxisMotion

DT = 0.001


def run(axis: AxisMotion, seconds: float, dt: float = DT) -> list[float]:
    """Step ``axis`` for ``seconds``; the velocity after each step."""
    velocities = []
    for _ in range(round(seconds / dt)):
        axis.step(dt)
        velocities.append(axis.velocity)
    return velocities


def test_move_is_trapezoidal_and_reaches_the_target_exactly() -> None:
    axis = AxisMotion(max_speed=10.0, acceleration=20.0)
    axis.move_to(10.0)
    velocities = run(axis, 2.0)
    # accelerate 0.5 s to 10, cruise, brake 0.5 s: 10 units take 1.5 s
    assert max(velocities) == pytest.approx(10.0)
    changes = [b - a for a, b in zip([0.0, *velocities], velocities, strict=False) if b != 0.0]
    assert max(abs(c) for c in changes) <= 20.0 * DT + 1e-9  # until the arrival step
    assert axis.position == 10.0 and axis.velocity == 0.0
    assert axis.target is None and not axis.moving and axis.mode == 'idle'
    arrival = next(i for i, v in enumerate(velocities) if i > 10 and v == 0.0)
    assert arrival * DT == pytest.approx(1.5, abs=0.01)


def test_short_move_is_triangular() -> None:
    axis = AxisMotion(max_speed=10.0, acceleration=20.0)
    axis.move_to(0.2)
    velocities = run(axis, 1.0)
    assert max(velocities) == pytest.approx(math.sqrt(20.0 * 0.2), rel=0.02)  # never cruises
    assert axis.position == 0.2


def test_separate_deceleration_and_move_speed() -> None:
    axis = AxisMotion(max_speed=10.0, acceleration=100.0, deceleration=5.0)
    axis.move_to(-5.0, speed=2.0)
    velocities = run(axis, 0.1)
    assert min(velocities) == pytest.approx(-2.0)  # the move's speed, not max_speed
    axis.stop()
    run(axis, 0.2)
    assert axis.velocity == pytest.approx(-1.0, abs=0.01)  # braking at 5 /s^2
    run(axis, 0.3)
    assert axis.velocity == 0.0 and axis.mode == 'idle'


def test_reversal_brakes_through_zero_then_runs_back() -> None:
    axis = AxisMotion(max_speed=4.0, acceleration=8.0)
    axis.jog(4.0)
    run(axis, 1.0)
    assert axis.velocity == 4.0
    turn_from = axis.position
    axis.move_to(0.0)
    velocities = run(axis, 0.25)
    assert velocities[-1] == pytest.approx(2.0)  # still braking forward, not reversed at once
    assert axis.position > turn_from
    run(axis, 5.0)
    assert axis.position == 0.0 and axis.velocity == 0.0


def test_jog_runs_until_stopped_and_stop_decelerates() -> None:
    axis = AxisMotion(max_speed=1.0, acceleration=10.0)
    axis.jog(5.0)  # beyond max_speed: clamped
    assert axis.jog_velocity == 1.0
    run(axis, 1.0)
    assert axis.velocity == 1.0 and axis.mode == 'jog'
    axis.stop()
    assert axis.mode == 'stopping' and axis.moving
    came_to_rest = axis.step(0.05)
    assert not came_to_rest and axis.velocity == pytest.approx(0.5)
    assert axis.step(0.1)  # reports the moment it comes to rest
    assert axis.velocity == 0.0 and axis.mode == 'idle' and not axis.moving


def test_immediate_stop_halts_at_once() -> None:
    axis = AxisMotion(max_speed=1.0, acceleration=10.0)
    axis.move_to(5.0)
    run(axis, 0.5)
    at = axis.position
    axis.stop(immediate=True)
    assert axis.velocity == 0.0 and axis.target is None
    run(axis, 0.1)
    assert axis.position == at


def test_position_limits_clamp_targets_and_stop_jogs() -> None:
    axis = AxisMotion(max_speed=2.0, acceleration=50.0, min_position=-1.0, max_position=1.0)
    axis.move_to(3.0)
    assert axis.target == 1.0
    run(axis, 2.0)
    assert axis.position == 1.0 and axis.limit_reached == 1
    axis.jog(-2.0)
    assert axis.step(2.0)  # runs into the lower limit and stops there
    assert axis.position == -1.0 and axis.velocity == 0.0
    assert axis.jog_velocity is None and axis.limit_reached == -1
    axis.set_limits(None, None)
    axis.jog(-2.0)
    run(axis, 0.5)
    assert axis.position < -1.5 and axis.limit_reached == 0


def test_speed_zero_move_holds_and_target_change_mid_move() -> None:
    axis = AxisMotion(max_speed=5.0, acceleration=20.0)
    axis.move_to(4.0, speed=0.0)
    run(axis, 0.2)
    assert axis.position == 0.0 and axis.target == 4.0
    axis.speed = 5.0
    run(axis, 0.3)
    axis.target = 1.0  # a new target while moving (the device's MOT_Update)
    run(axis, 3.0)
    assert axis.position == 1.0 and axis.velocity == 0.0


def test_one_long_step_equals_many_short_ones() -> None:
    lazy, fine = AxisMotion(max_speed=0.8, acceleration=8.0), AxisMotion(0.8, 8.0)
    for axis in (lazy, fine):
        axis.move_to(0.5)
    lazy.step(0.4)
    run(fine, 0.4, dt=0.005)
    assert lazy.position == pytest.approx(fine.position, abs=1e-9)


def test_subclass_goal_and_arrival_hooks() -> None:
    class Homing(AxisMotion):
        homed = False

        def goal(self):
            return 0.0, 1.0

        def on_arrival(self) -> None:
            self.homed = True

    axis = Homing(max_speed=5.0, acceleration=10.0, position=0.5)
    run(axis, 2.0)
    assert axis.position == 0.0 and axis.homed
    assert axis.snapshot() == {'position': 0.0, 'velocity': 0.0, 'target': None,
                               'mode': 'idle', 'moving': False}
