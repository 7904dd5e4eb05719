"""The device drivers the demo runs, each against its own simulator.

A target is skipped by the demo while its package is not built. Every target
keeps its pseudo-terminal links, presets file and password file in the demo's
temporary directory (``target.workdir``), so nothing is left in /tmp and two
demos on one machine do not collide. Each simulator binds 127.0.0.1 only.

Values and why (limits from each package's config/<pkg>_sim.yaml and README):

- capture_driver: TCP 127.0.0.1:<free port>; move pan 0.4, tilt -0.2 rad (limits ±π, ±π/2);
  jog pan 0.3 rad/s (max 1.5); the device's own SCN snake scan over pan ±0.2, tilt 0..0.2.
- canaero_turret_driver: slcan over a pty; move yaw 0.4, pitch 0.2 rad (pitch -0.52..1.05);
  jog yaw 0.3 rad/s (max 1.05); driver-side zigzag.
- kessler_kos_driver: TCP with a password (from a file); move pan 3.0, tilt -2.0 rad (the
  simulator's calibrated ranges are pan 0..628 rad, tilt -251..0); jog pan 3 rad/s (toward
  the end of travel); driver-side sector, the only scan the driver has; then a playback.
- ucamera_driver: UCSP over a pty; move pan 0.4, tilt -0.3 rad (limits ±π, ±π/2); jog pan
  0.3 rad/s (max 1.0); driver-side sector.

The Kessler joints are ordered ``[pan, tilt, slider]`` (motor addresses 2, 3, 1): the base
node's scans sweep the *first* joint, and with the package default ``[slider, pan, tilt]``
a sector "pan" scan would drive the slider.
"""

from __future__ import annotations

import math

from builtin_interfaces.msg import Duration
from demo import DemoTarget
from sensor_msgs.msg import NavSatFix
from std_msgs.msg import Float64
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from gimbal_driver_common.ros.testing import RosTestClient
from gimbal_driver_common.testing import wait_for
from gimbal_msgs.action import Home
from gimbal_msgs.msg import PlaybackStatus
from gimbal_msgs.srv import LoadTrajectory, StartScan

KESSLER_PASSWORD = 'demo-kos-secret'
KESSLER_JOINTS = ('pan', 'tilt', 'slider')
# rad (slider: 2π per motor rotation as well), inside the simulator's --precalibrated ranges
# (pan 0..100 rotations, tilt 0..-40, slider 0..200) and well under MaxMaxMoveSpeed.
KESSLER_KEYFRAMES = ((0.0, (2.0, -2.0, 5.0)), (2.5, (40.0, -30.0, 40.0)),
                     (5.0, (80.0, -10.0, 20.0)))


def common_params(target: DemoTarget) -> list[str]:
    """Parameters every driver gets in the demo: a modest rate (2 shared cores), quick
    reconnects, and driver-side presets in the demo's temporary directory."""
    return ['publish_rate:=20.0', 'reconnect_period:=0.5', 'diagnostics_period:=0.5',
            f'presets_file:={target.workdir / (target.node_name + "_presets.yaml")}']


def run_home(target: DemoTarget, ros: RosTestClient) -> str:
    result, _, feedback = ros.run_action(Home, target.ns('home'), Home.Goal(), timeout=60)
    if not result.success:
        raise RuntimeError(result.message)
    return f'{result.message} ({len(feedback)} feedback messages)'


# ----------------------------------------------------------------------------- Capture
def capture_target() -> DemoTarget:
    return DemoTarget(
        title='Capture Systems pan-tilt pedestal (TCP)',
        package='capture_driver',
        node_executable='capture_driver_node',
        node_name='capture_driver',
        sim_executable='capture_sim',
        sim_args=lambda t: ['--port', str(t.port)],
        node_params=lambda t: [*common_params(t), 'transport:=tcp', 'host:=127.0.0.1',
                               f'port:={t.port}', 'status_period:=0.2', 'default_speed:=1.0',
                               'acceleration:=6.0'],
        move_goal=(0.4, -0.2),
        jog_velocity=0.3,
        scan=StartScan.Request(pattern='snake', pan_min=-0.2, pan_max=0.2, tilt_min=0.0,
                               tilt_max=0.2, speed=0.5, tilt_step=0.1),
        extra_steps=[('home', run_home)],
    )


# ----------------------------------------------------------------------------- CANaerospace
def canaero_cover_and_fix(target: DemoTarget, ros: RosTestClient) -> str:
    reply = ros.call(SetBool, target.ns('set_cover'), SetBool.Request(data=True))
    if not reply.success:
        raise RuntimeError(reply.message)
    fix = ros.wait_for_message(target.ns('fix'), NavSatFix, timeout=10)
    return (f'set_cover true: {reply.message}; GNSS fix {fix.latitude:.4f}, '
            f'{fix.longitude:.4f}, {fix.altitude:.1f} m')


def canaero_target() -> DemoTarget:
    return DemoTarget(
        title='CANaerospace turret (slcan over a pty)',
        package='canaero_turret_driver',
        node_executable='canaero_turret_driver_node',
        node_name='canaero_turret_driver',
        sim_executable='canaero_turret_sim',
        sim_args=lambda t: ['--link', str(t.workdir / 'canaero_tty')],
        node_params=lambda t: [*common_params(t), 'can_interface:=slcan',
                               f'can_channel:={t.workdir / "canaero_tty"}',
                               "can_options:=['sleep_after_open=0']", 'service_timeout:=0.3',
                               "transmission_intervals:=['yaw_position=20','pitch_position=20']",
                               'actuator_mode:=auto_brake'],
        joints=('yaw', 'pitch'),
        move_goal=(0.4, 0.2),
        jog_joint='yaw',
        jog_velocity=0.3,
        scan=StartScan.Request(pattern='zigzag', pan_min=-0.3, pan_max=0.3, tilt_min=0.0,
                               tilt_max=0.2, speed=0.5, tilt_step=0.1),
        extra_steps=[('cover+gnss', canaero_cover_and_fix)],
    )


# ----------------------------------------------------------------------------- Kessler
def kessler_playback(target: DemoTarget, ros: RosTestClient) -> str:
    """Load a 3-axis keyframe move, set it up (return to the first key frame), play it and
    wait for the device's FullStop."""
    trajectory = JointTrajectory(joint_names=list(KESSLER_JOINTS))
    for t, values in KESSLER_KEYFRAMES:
        trajectory.points.append(JointTrajectoryPoint(
            positions=list(values),
            time_from_start=Duration(sec=int(t), nanosec=round(t % 1 * 1e9))))
    statuses = ros.subscribe(target.ns('playback_status'), PlaybackStatus)
    loaded = ros.call(LoadTrajectory, target.ns('load_trajectory'), LoadTrajectory.Request(
        playback_mode=LoadTrajectory.Request.MODE_LIVE_MOTION, keyframes=trajectory))
    if not loaded.success:
        raise RuntimeError(f'load_trajectory: {loaded.message}')
    start = len(statuses)
    setup = ros.call(Trigger, target.ns('setup_playback'), Trigger.Request(), timeout=60)
    if not setup.success:
        raise RuntimeError(f'setup_playback: {setup.message}')
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

    end = wait_for(full_stop, 60, 'playback FullStop', interval=0.1)
    target.note = ''
    names = [s.status_name for s in list(statuses)[start:]]
    ends = ', '.join(f'{n}={p:.1f}' for n, p in zip(end.joint_names, end.positions,
                                                     strict=False))
    return (f'{len(KESSLER_KEYFRAMES)} key frames on {len(KESSLER_JOINTS)} axes, '
            f'{KESSLER_KEYFRAMES[-1][0]:g} s: {" -> ".join(names)} at [{ends}]')


def kessler_target() -> DemoTarget:
    def params(t: DemoTarget) -> list[str]:
        password_file = t.workdir / 'kessler_password'
        password_file.write_text(KESSLER_PASSWORD + '\n', encoding='utf-8')
        password_file.chmod(0o600)
        scale = 2 * math.pi
        return [*common_params(t), 'host:=127.0.0.1', f'port:={t.port}',
                f'password_file:={password_file}', 'discovery_bind:=127.0.0.1',
                f'joint_names:={list(KESSLER_JOINTS)}', 'motor_addresses:=[2, 3, 1]',
                f'joint_scales:=[{scale}, {scale}, {scale}]', 'poll_period:=0.05']

    return DemoTarget(
        title='Kessler kOS CineShooter (TCP, password)',
        package='kessler_kos_driver',
        node_executable='kessler_kos_driver_node',
        node_name='kessler_kos_driver',
        sim_executable='kessler_kos_sim',
        sim_args=lambda t: ['--port', str(t.port), '--password', KESSLER_PASSWORD,
                            '--precalibrated', '--discovery-port', '0'],
        node_params=params,
        joints=KESSLER_JOINTS,
        move_goal=(3.0, -2.0),
        jog_joint='pan',
        jog_velocity=3.0,
        scan=StartScan.Request(pattern='sector', pan_min=1.0, pan_max=6.0, speed=4.0),
        extra_steps=[('playback', kessler_playback)],
    )


# ----------------------------------------------------------------------------- U-Camera
def ucamera_zoom(target: DemoTarget, ros: RosTestClient) -> str:
    """Zoom to half tele; repeat the command until the gimbal reports it (a single message
    right after discovery can be lost)."""
    zooms = ros.subscribe(target.ns('zoom'), Float64)

    def reached() -> bool:
        ros.publish(target.ns('zoom_command'), Float64(data=0.5))
        return any(abs(m.data - 0.5) < 1e-3 for m in list(zooms)) or target.stop.is_set()

    wait_for(reached, 15, 'the reported zoom 0.5', interval=0.2)
    return 'zoom 0.5 commanded on ~/zoom_command and reported on ~/zoom'


def ucamera_target() -> DemoTarget:
    return DemoTarget(
        title='Airelectronics U-Camera (UCSP over a pty)',
        package='ucamera_driver',
        node_executable='ucamera_driver_node',
        node_name='ucamera_driver',
        sim_executable='ucamera_sim',
        sim_args=lambda t: ['--link', str(t.workdir / 'ucamera_tty')],
        node_params=lambda t: [*common_params(t), f'serial_port:={t.workdir / "ucamera_tty"}',
                               'telemetry_rate:=50', 'gps_feed:=external'],
        move_goal=(0.4, -0.3),
        jog_velocity=0.3,
        scan=StartScan.Request(pattern='sector', pan_min=-0.3, pan_max=0.3, speed=0.5),
        extra_steps=[('zoom', ucamera_zoom), ('home', run_home)],
    )


def driver_targets() -> list[DemoTarget]:
    return [capture_target(), canaero_target(), kessler_target(), ucamera_target()]
