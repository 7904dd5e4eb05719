"""Frame conversions of the node (ENU/FLU -> NED/FRD) and the feed rate limiter."""

import math

import pytest

pytestmark = pytest.mark.ros
pytest.importorskip("rclpy")
pytest.importorskip("gimbal_msgs", reason="needs the built workspace: make build; "
                    "source scripts/ros_env.sh")

from ucamera_driver.node import (  # noqa: E402
    RateLimiter,
    enu_flu_to_ned_frd,
    quaternion_to_euler,
)


def quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


@pytest.mark.parametrize("angles", [(0.1, -0.2, 0.3), (-1.0, 0.5, -2.5), (0.0, 0.0, 0.0)])
def test_quaternion_to_euler_round_trip(angles) -> None:
    assert quaternion_to_euler(*quaternion(*angles)) == pytest.approx(angles, abs=1e-9)


@pytest.mark.parametrize(
    ("enu", "ned"),
    [
        ((0.0, 0.0, 0.0), (math.pi / 2, 0.0, 0.0)),  # facing east: heading 90
        ((0.0, 0.0, math.pi / 2), (0.0, 0.0, 0.0)),  # facing north: heading 0
        ((0.0, 0.0, -math.pi / 2), (math.pi, 0.0, 0.0)),  # facing south
        ((0.0, -0.2, math.pi / 2), (0.0, 0.2, 0.0)),  # FLU pitch -0.2 = nose up
        ((0.3, 0.0, math.pi / 2), (0.0, 0.0, 0.3)),  # right wing down in both
    ],
)
def test_enu_flu_to_ned_frd(enu, ned) -> None:
    yaw, pitch, roll = enu_flu_to_ned_frd(*enu)
    assert (abs(yaw), pitch, roll) == pytest.approx((abs(ned[0]), ned[1], ned[2]), abs=1e-9)


def test_rate_limiter() -> None:
    limiter = RateLimiter(10.0)
    assert limiter.allow("imu", now=1.0)
    assert not limiter.allow("imu", now=1.05)
    assert limiter.allow("fix", now=1.05)
    assert limiter.allow("imu", now=1.11)
    assert RateLimiter(0.0).allow("x", now=0.0) and RateLimiter(0.0).allow("x", now=0.0)
