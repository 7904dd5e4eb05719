"""A motor's speed from its position reports (no ROS, no device): kOS reports positions
only, each timed when it is read, so the speed must not follow the reading's jitter.
The stop confirmation trusts it: a speed that reads 0 while the axis moves ends the
watch on a stop the device dropped (the 2026-12-02 CI failure of the dropped dead-man
stop), and a speed that reads tens of rad/s puts its deadline minutes away."""

from __future__ import annotations

import pytest

from kessler_kos_driver.client_types import VELOCITY_SPAN_S, MotorState

SPEED = 2.0  # rot/s, the true speed of the motor in these tests


def reports(motor: MotorState, times: list[float]) -> None:
    """Reports of a motor turning at SPEED, measured at ``times``, each read then."""
    for when in times:
        motor.report(SPEED * when, when)


def test_the_speed_is_the_travel_over_the_span():
    motor = MotorState(1)
    reports(motor, [i * 0.02 for i in range(20)])   # 50 Hz
    assert motor.velocity == pytest.approx(SPEED)
    assert motor.position == pytest.approx(SPEED * 0.38)
    assert motor.stamp == pytest.approx(0.38)


def test_two_reports_read_in_one_burst_give_no_speed_of_their_own():
    motor = MotorState(1)
    reports(motor, [0.0, 0.1, 0.2])
    # the device measured 0.21 and 0.25, the machine read both at 0.2501: their own
    # difference would read 0.04 / 0.0001 = 400 rot/s
    motor.report(SPEED * 0.21, 0.2500)
    motor.report(SPEED * 0.25, 0.2501)
    assert motor.velocity == pytest.approx(SPEED, rel=0.35)


def test_a_repeated_position_inside_the_span_does_not_read_as_rest():
    motor = MotorState(1)
    reports(motor, [0.0, 0.05, 0.1, 0.15])
    motor.report(SPEED * 0.15, 0.16)   # the same position again, read 10 ms later
    assert motor.velocity == pytest.approx(SPEED, rel=0.2)


def test_a_motor_at_rest_reads_zero_once_the_span_has_passed():
    motor = MotorState(1)
    reports(motor, [0.0, 0.05, 0.1])
    for i in range(1, 8):
        motor.report(SPEED * 0.1, 0.1 + i * 0.02)   # stopped at 0.1
    assert motor.velocity == 0.0


def test_no_speed_before_the_reports_span_the_window():
    motor = MotorState(1)
    motor.report(1.0, 0.0)
    motor.report(2.0, VELOCITY_SPAN_S / 2)
    assert motor.velocity == 0.0 and motor.position == 2.0


def test_the_history_stays_short():
    motor = MotorState(1)
    reports(motor, [i * 0.001 for i in range(5000)])  # 1 kHz for 5 s
    assert len(motor.recent) <= VELOCITY_SPAN_S / 0.001 + 2
