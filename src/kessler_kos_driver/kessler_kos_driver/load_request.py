"""The LoadTrajectory request in the device's terms (no rclpy): start time, keyframes and
Bezier segments read from the request's messages and checked against the joint limits
before anything reaches the device. Apart from the node so it reads in one sitting.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping

from gimbal_driver_common.joint_command import CommandError, JointLimits

from .moves import Keyframe


def start_time(stamp) -> int:
    """LoadTrajectory.start_time as UnixTime (0 = not used); a past date is refused."""
    if stamp.sec == 0 and stamp.nanosec == 0:
        return 0
    value = math.ceil(stamp.sec + stamp.nanosec * 1e-9)   # UnixTime is whole seconds
    now = time.time()
    if value <= now:
        raise CommandError(f'start_time {value} (UnixTime s) is {now - value:.0f} s in the '
                           'past; give a future date or use start_delay')
    if value > 0xFFFFFFFF:
        raise CommandError(f'start_time {value} is beyond UnixTime (UInt32) 4294967295')
    return value


def keyframes(trajectory, limits: Mapping[str, JointLimits]) -> list[Keyframe]:
    """Keyframes of a LoadTrajectory request (trajectory_msgs/JointTrajectory), each joint
    known and every position within its limits."""
    names = list(trajectory.joint_names)
    if not names or len(set(names)) != len(names):
        raise CommandError(f'keyframes.joint_names must be unique and non-empty: {names}')
    unknown = [n for n in names if n not in limits]
    if unknown:
        raise CommandError(f'unknown joint(s) {unknown}; this device has '
                           f'{list(limits)}')
    frames = []
    for index, point in enumerate(trajectory.points):
        if len(point.positions) != len(names):
            raise CommandError(f'keyframe {index}: {len(point.positions)} positions for '
                               f'{len(names)} joints')
        if point.velocities and len(point.velocities) != len(names):
            raise CommandError(f'keyframe {index}: velocities must be empty or one per '
                               'joint')
        positions = dict(zip(names, point.positions, strict=True))
        for name, value in positions.items():
            joint = limits[name]
            if not math.isfinite(value) or not (
                    joint.position_min <= value <= joint.position_max):
                raise CommandError(f'keyframe {index}: joint {name!r} position {value} is '
                                   f'outside [{joint.position_min}, '
                                   f'{joint.position_max}]')
        velocities = (dict(zip(names, point.velocities, strict=True))
                      if point.velocities else None)
        t = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
        frames.append(Keyframe(t, positions, velocities))
    return frames


def segments(axes, limits: Mapping[str, JointLimits]) -> dict[str, list[tuple[float, ...]]]:
    """Explicit Bezier segments of a LoadTrajectory request, per known joint, each once."""
    segments: dict[str, list[tuple[float, ...]]] = {}
    for axis in axes:
        if axis.joint_name not in limits:
            raise CommandError(f'unknown joint {axis.joint_name!r}; this device has '
                               f'{list(limits)}')
        if axis.joint_name in segments:
            raise CommandError(f'joint {axis.joint_name!r} is given twice')
        segments[axis.joint_name] = [
            (s.p0_time, s.p0_position, s.p1_time, s.p1_position, s.p2_time,
             s.p2_position, s.p3_time, s.p3_position) for s in axis.segments]
    return segments
