"""Angle and attitude conversions of gimbal_driver_common.orientation."""

import math

import pytest

from gimbal_driver_common.orientation import (
    euler_from_quaternion,
    quaternion_from_euler,
    wrap_angle,
)


@pytest.mark.parametrize("angles", [(0.1, -0.2, 0.3), (-1.0, 0.5, -2.5), (0.0, 0.0, 0.0)])
def test_quaternion_to_euler_round_trip(angles) -> None:
    assert euler_from_quaternion(*quaternion_from_euler(*angles)) == pytest.approx(
        angles, abs=1e-9)


def test_quaternion_of_a_yaw_is_a_rotation_about_z() -> None:
    x, y, z, w = quaternion_from_euler(0.0, 0.0, math.pi / 2)
    assert (x, y) == (0.0, 0.0)
    assert (z, w) == pytest.approx((math.sqrt(0.5), math.sqrt(0.5)))
    assert math.hypot(x, y, z, w) == pytest.approx(1.0)


def test_pitch_past_the_pole_by_rounding_is_clamped() -> None:
    s = math.sqrt(0.5) * (1 + 1e-12)  # 2(wy - zx) a hair above 1
    assert euler_from_quaternion(0.0, s, 0.0, s)[1] == pytest.approx(math.pi / 2)


@pytest.mark.parametrize(("angle", "wrapped"), [
    (0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi / 2, -math.pi / 2),
    (-5 * math.pi / 2, -math.pi / 2), (7.0, 7.0 - 2 * math.pi)])
def test_wrap_angle_is_in_minus_pi_exclusive_to_pi(angle, wrapped) -> None:
    assert wrap_angle(angle) == pytest.approx(wrapped, abs=1e-12)
