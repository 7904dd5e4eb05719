"""The Kessler driver's own step in ``scripts/demo.py`` (named in its registry spec); it
waits through the demo's ROS client, so it imports no test support."""

from __future__ import annotations

from typing import Any

from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from gimbal_msgs.msg import PlaybackStatus
from gimbal_msgs.srv import LoadTrajectory

PLAYBACK_JOINTS = ('pan', 'tilt', 'slider')
#: (s, (pan rad, tilt rad, slider m)): inside the simulator's example rig in SI
#: (registration.SIM_RIG: pan -pi..pi, tilt -pi/2..pi/2, slider 0..1.5 m) and well under
#: MaxMaxMoveSpeed and MaxMaxAcceleration: pan sweeps from 30 deg right to 140 deg left, the
#: tilt rises above the horizon and back, the carriage runs from 0.1 m out to 0.9 m and back
#: to 0.6 m
KEYFRAMES = ((0.0, (-0.5, -0.2, 0.1)), (3.0, (1.2, 0.4, 0.9)), (6.0, (2.5, 0.1, 0.6)))


def playback(target: Any, ros: Any) -> str:
    """Load a 3-axis keyframe move, set it up (return to the first key frame), play it and
    wait for the device's FullStop."""
    trajectory = JointTrajectory(joint_names=list(PLAYBACK_JOINTS))
    for seconds, values in KEYFRAMES:
        point = JointTrajectoryPoint(positions=list(values))
        point.time_from_start.sec = int(seconds)
        point.time_from_start.nanosec = round(seconds % 1 * 1e9)
        trajectory.points.append(point)
    statuses = ros.subscribe(target.ns('playback_status'), PlaybackStatus)
    loaded = ros.call(LoadTrajectory, target.ns('load_trajectory'), LoadTrajectory.Request(
        playback_mode=LoadTrajectory.Request.MODE_LIVE_MOTION, keyframes=trajectory))
    if not loaded.success:
        raise RuntimeError(f'load_trajectory: {loaded.message}')
    start = len(statuses)
    # for the demo's plot: setup returns to the first key frame, the playback follows them
    target.commanded('target', positions=dict(zip(PLAYBACK_JOINTS, KEYFRAMES[0][1], strict=True)))
    setup = ros.call(Trigger, target.ns('setup_playback'), Trigger.Request(), timeout=60)
    if not setup.success:
        raise RuntimeError(f'setup_playback: {setup.message}')
    target.commanded('keyframes', joint_names=list(PLAYBACK_JOINTS),
                     points=[[seconds, list(values)] for seconds, values in KEYFRAMES])
    played = ros.call(Trigger, target.ns('start_playback'), Trigger.Request())
    if not played.success:
        raise RuntimeError(f'start_playback: {played.message}')

    def full_stop() -> PlaybackStatus | None:
        """The FullStop that ends this playback (one after its StartForward)."""
        forward = False
        for status in list(statuses)[start:]:
            target.note = f'playback {status.status_name} {status.elapsed:.0%}'
            forward = forward or status.status == PlaybackStatus.START_FORWARD
            if (forward and status.status == PlaybackStatus.FULL_STOP) or target.stop.is_set():
                return status
        return None

    end = ros.wait_for(full_stop, 60, 'playback FullStop', interval=0.1)
    target.note = ''
    names = [s.status_name for s in list(statuses)[start:]]
    ends = ', '.join(f'{n}={p:.3f} {"m" if n == "slider" else "rad"}'
                     for n, p in zip(end.joint_names, end.positions, strict=False))
    return (f'{len(KEYFRAMES)} key frames on {len(PLAYBACK_JOINTS)} axes, '
            f'{KEYFRAMES[-1][0]:g} s: {" -> ".join(names)} at [{ends}]')
