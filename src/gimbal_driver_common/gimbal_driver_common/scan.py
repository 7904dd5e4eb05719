"""Driver-side scan patterns: waypoints for devices without their own scans.

Patterns follow gimbal_msgs/srv/StartScan: *sector* sweeps pan between its
limits at the current tilt; *zigzag* runs rows between the pan limits,
stepping tilt each row (boustrophedon); *square* walks rectangles that shrink
inward by ``tilt_step`` on every side.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

from gimbal_driver_common.errors import InvalidRequest
from gimbal_driver_common.joint_command import JointLimits

MAX_WAYPOINTS = 10000


class ScanError(InvalidRequest):
    """The scan request cannot be run; the message says which value and why."""


class ScanFields(Protocol):
    """The fields of a gimbal_msgs/srv/StartScan request that a scan reads (no ROS import
    here: the request message, or anything with the same fields)."""

    pattern: str
    pan_min: float
    pan_max: float
    tilt_min: float
    tilt_max: float
    speed: float
    tilt_step: float
    dwell: float


@dataclass(frozen=True)
class ScanRequest:
    pattern: str
    pan_min: float
    pan_max: float
    tilt_min: float
    tilt_max: float
    speed: float
    tilt_step: float
    dwell: float

    @classmethod
    def from_msg(cls, msg: ScanFields) -> ScanRequest:
        """Copy the fields of a gimbal_msgs/srv/StartScan request (duck-typed, no ROS import)."""
        return cls(
            pattern=str(msg.pattern).strip().lower(),
            pan_min=float(msg.pan_min), pan_max=float(msg.pan_max),
            tilt_min=float(msg.tilt_min), tilt_max=float(msg.tilt_max),
            speed=float(msg.speed), tilt_step=float(msg.tilt_step), dwell=float(msg.dwell),
        )


def _check_range(label: str, low: float, high: float, limits: JointLimits) -> None:
    for value in (low, high):
        if not math.isfinite(value):
            raise ScanError(f'{label} limit {value} is not finite')
    if low > high:
        raise ScanError(f'{label}_min {low:.4f} > {label}_max {high:.4f}')
    if low < limits.position_min or high > limits.position_max:
        raise ScanError(
            f'{label} range [{low:.4f}, {high:.4f}] outside the joint limits '
            f'[{limits.position_min:.4f}, {limits.position_max:.4f}]'
        )


def check_scan(
    request: ScanRequest,
    joints: Sequence[str],
    limits: Mapping[str, JointLimits],
    patterns: Sequence[str],
    device: str = 'this driver',
) -> tuple[str, str]:
    """The one check of a scan request, driver-side or device scan: the pattern, the
    joints, speed and dwell, the pan range and (all but *sector*, which stays at the
    current tilt) the tilt range and step. Returns (pan, tilt); raises ScanError."""
    if request.pattern not in patterns:
        raise ScanError(
            f'pattern {request.pattern!r} not available; {device} has {list(patterns)}'
        )
    if len(joints) < 2:
        raise ScanError('a scan needs a pan and a tilt joint')
    pan, tilt = joints[0], joints[1]
    if not math.isfinite(request.speed) or request.speed <= 0:
        raise ScanError(f'speed {request.speed} must be > 0 rad/s')
    if request.speed > limits[pan].velocity_max:
        raise ScanError(
            f'speed {request.speed:.4f} exceeds {pan} velocity_max {limits[pan].velocity_max:.4f}'
        )
    if not math.isfinite(request.dwell) or request.dwell < 0:
        raise ScanError(f'dwell {request.dwell} must be >= 0 s')
    _check_range('pan', request.pan_min, request.pan_max, limits[pan])
    if request.pattern != 'sector':
        _check_range('tilt', request.tilt_min, request.tilt_max, limits[tilt])
        step = request.tilt_step
        if not math.isfinite(step) or step <= 0:
            raise ScanError(f'tilt_step {step} must be > 0 rad for {request.pattern}')
    return pan, tilt


def plan_scan(
    request: ScanRequest,
    joints: Sequence[str],
    current: Mapping[str, float],
    limits: Mapping[str, JointLimits],
    patterns: Sequence[str],
) -> list[dict[str, float]]:
    """Waypoints (joint -> position) for one period of the pattern; raises ScanError."""
    pan, tilt = check_scan(request, joints, limits, patterns)
    step = request.tilt_step
    if request.pattern == 'sector':
        if pan not in current or tilt not in current:
            raise ScanError('no current position yet: cannot scan at the current tilt')
        tilt_now = current[tilt]
        return [{pan: request.pan_min, tilt: tilt_now}, {pan: request.pan_max, tilt: tilt_now}]
    if request.pattern == 'zigzag':
        rows = math.floor((request.tilt_max - request.tilt_min) / step + 1e-9) + 1
        if rows * 2 > MAX_WAYPOINTS:
            raise ScanError(f'{rows} rows is too many; increase tilt_step')
        waypoints = []
        for row in range(rows):
            t = request.tilt_min + row * step
            first, last = (
                (request.pan_min, request.pan_max) if row % 2 == 0
                else (request.pan_max, request.pan_min)
            )
            waypoints += [{pan: first, tilt: t}, {pan: last, tilt: t}]
        return waypoints
    if request.pattern == 'square':
        waypoints = []
        p0, p1, t0, t1 = request.pan_min, request.pan_max, request.tilt_min, request.tilt_max
        while p0 <= p1 and t0 <= t1 and len(waypoints) < MAX_WAYPOINTS:
            waypoints += [
                {pan: p0, tilt: t1}, {pan: p1, tilt: t1}, {pan: p1, tilt: t0}, {pan: p0, tilt: t0},
            ]
            p0, p1, t0, t1 = p0 + step, p1 - step, t0 + step, t1 - step
        return waypoints
    raise ScanError(f'pattern {request.pattern!r} has no driver-side implementation')
