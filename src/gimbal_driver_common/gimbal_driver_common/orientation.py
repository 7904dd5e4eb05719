"""Angle and attitude conversions shared by the drivers (pure Python, no ROS).

Quaternions are (x, y, z, w) as in geometry_msgs/Quaternion; Euler angles are the ZYX
(yaw, then pitch, then roll) convention of REP-103 and tf2's ``setRPY``.
"""

from __future__ import annotations

import math


def wrap_angle(angle: float) -> float:
    """``angle`` in (-pi, pi]."""
    wrapped = math.remainder(angle, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def quaternion_from_euler(roll: float, pitch: float,
                          yaw: float) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of ZYX Euler angles (roll, pitch, yaw)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def euler_from_quaternion(x: float, y: float, z: float,
                          w: float) -> tuple[float, float, float]:
    """ZYX Euler angles (roll, pitch, yaw) of a unit quaternion; pitch is clamped to
    +-pi/2 against rounding just past the poles."""
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw
