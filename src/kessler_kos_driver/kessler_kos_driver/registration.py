"""kessler_kos_driver in the driver registry (see :mod:`gimbal_driver_common.registry`).

The joints are ordered ``[pan, tilt, slider]`` (motor addresses 2, 3, 1): the base node's
scans sweep the *first* joint, and with the package default ``[slider, pan, tilt]`` a
sector "pan" scan would drive the slider. Every joint is 2π rad (slider: 2π per motor
rotation as well) per motor rotation. Demo and soak values lie inside the simulator's
``--precalibrated`` ranges (pan 0..100 rotations = 0..628 rad, tilt 0..-40, slider
0..200): move pan 3.0, tilt -2.0 rad; jog pan 3 rad/s (toward the end of travel);
driver-side sector, the only scan the driver has; then a keyframe playback.
"""

import math

from gimbal_driver_common.registry import BenchSettings, DemoSettings, DriverSpec, SoakSettings

SPEC = DriverSpec(
    name='kessler_kos',
    title='Kessler kOS CineShooter (TCP, password)',
    package='kessler_kos_driver',
    node_executable='kessler_kos_driver_node',
    node_name='kessler_kos_driver',
    sim_executable='kessler_kos_sim',
    node_class='kessler_kos_driver.node:KosDriverNode',
    description='kessler_kos_driver.urdf',
    joints=('pan', 'tilt', 'slider'),
    move_goal=(3.0, -2.0),
    sim_arguments=('--port', '{port}', '--password', '{password}', '--precalibrated',
                   '--discovery-port', '0'),
    node_parameters={'host': '127.0.0.1', 'port': '{port}', 'password_file': '{password_file}',
                     'discovery_bind': '127.0.0.1', 'joint_names': ['pan', 'tilt', 'slider'],
                     'motor_addresses': [2, 3, 1], 'joint_scales': [math.tau] * 3},
    password='kos-sim-secret',
    sim_handle='kessler_kos_driver.sim_handle:KesslerSimHandle',
    demo=DemoSettings(
        jog_joint='pan', jog_velocity=3.0,
        scan={'pattern': 'sector', 'pan_min': 1.0, 'pan_max': 6.0, 'speed': 4.0},
        extra_steps=(('playback', 'kessler_kos_driver.demo_steps:playback'),)),
    soak=SoakSettings(
        joint_ranges={'pan': (1.0, 20.0), 'tilt': (-20.0, -1.0), 'slider': (1.0, 20.0)},
        extra_services={'take_picture': 'std_srvs/srv/Trigger',
                        'stop_playback': 'std_srvs/srv/Trigger',
                        'load_trajectory': 'gimbal_msgs/srv/LoadTrajectory'}),
    # the generic benchmark plus the kOS codec (bench/bench_kessler_kos.py); rad on 'pan',
    # inside the calibrated 0..100 rotations
    bench=BenchSettings(module='kessler_kos', stream_joint='pan', stream_base=20.0,
                        stream_tolerance=2e-5 * math.tau, move_targets=(10.0, 40.0)),
)
