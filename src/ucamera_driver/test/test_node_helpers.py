"""The node's feed and report rate limiter (the frame conversions are tested in
test_device.py, next to the adapter that owns them)."""

import pytest

pytestmark = pytest.mark.ros
pytest.importorskip("rclpy")
pytest.importorskip("gimbal_msgs", reason="needs the built workspace: make build; "
                    "source scripts/ros_env.sh")

from ucamera_driver.node import RateLimiter  # noqa: E402


def test_rate_limiter() -> None:
    limiter = RateLimiter(10.0)
    assert limiter.allow("imu", now=1.0)
    assert not limiter.allow("imu", now=1.05)
    assert limiter.allow("fix", now=1.05)
    assert limiter.allow("imu", now=1.11)
    assert RateLimiter(0.0).allow("x", now=0.0) and RateLimiter(0.0).allow("x", now=0.0)
