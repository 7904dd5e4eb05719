"""kessler_kos_driver in the driver registry (see :mod:`gimbal_driver_common.registry`).

The joints are ordered ``[pan, tilt, slider]`` (motor addresses 2, 3, 1): the base node's
scans sweep the *first* joint, and with the package default ``[slider, pan, tilt]`` a
sector "pan" scan would drive the slider.

Units: the simulator's ``--precalibrated`` axes (``sim.DEFAULT_RANGES``: slider
0..200 rotations, pan 0..100, tilt 0..-40) are the example rig of the node's defaults and
the URDF, in SI, through ``calibrated_spans`` and ``joint_offsets`` (:data:`SIM_RIG`):

* slider: 1.5 m of rail from the begin mark (0 m) over 200 rotations: 7.5 mm per rotation;
* pan: a full turn, -pi at the begin mark to +pi, over 100 rotations (a 1:100 head);
* tilt: pi, from -pi/2 at the begin mark (looking down) to +pi/2, over -40 rotations (the
  motor counts down as the tilt rises: the span's sign is the joint's, the end's the motor's).

So the demo, the soak and the benchmark show metres and radians: moves, jogs, scans, presets
and the keyframe playback below are SI values inside those ranges, and the motors start at
their begin marks (slider 0 m, pan -pi, tilt -pi/2).
"""

import math
from dataclasses import dataclass

from gimbal_driver_common.registry import BenchSettings, DemoSettings, DriverSpec, SoakSettings


@dataclass(frozen=True)
class RigJoint:
    """One joint of the simulator's example rig, SI (m or rad)."""

    span: float       # calibrated_spans: begin mark -> end mark
    offset: float     # joint_offsets: the value at the begin mark
    lower: float      # position_min
    upper: float      # position_max
    velocity: float   # velocity_max


#: joint -> the simulator's example rig in SI (equal to the node's default limits, the URDF
#: and config/kessler_kos_driver_sim.yaml; test/test_units.py checks all of them)
SIM_RIG = {
    'slider': RigJoint(1.5, 0.0, 0.0, 1.5, 0.5),
    'pan': RigJoint(2 * math.pi, -math.pi, -math.pi, math.pi, 1.5),
    'tilt': RigJoint(math.pi, -math.pi / 2, -math.pi / 2, math.pi / 2, 1.0),
}
JOINTS = ('pan', 'tilt', 'slider')


def sim_rig_parameters(joints: tuple[str, ...] = JOINTS) -> dict[str, list[float]]:
    """The unit and limit parameters of :data:`SIM_RIG` for ``joints``, in that order."""
    rig = [SIM_RIG[name] for name in joints]
    return {'calibrated_spans': [j.span for j in rig], 'joint_offsets': [j.offset for j in rig],
            'position_min': [j.lower for j in rig], 'position_max': [j.upper for j in rig],
            'velocity_max': [j.velocity for j in rig]}


SPEC = DriverSpec(
    name='kessler_kos',
    title='Kessler kOS CineShooter (TCP, password)',
    package='kessler_kos_driver',
    node_executable='kessler_kos_driver_node',
    node_name='kessler_kos_driver',
    sim_executable='kessler_kos_sim',
    node_class='kessler_kos_driver.node:KosDriverNode',
    description='kessler_kos_driver.urdf',
    joints=JOINTS,
    move_goal=(0.8, 0.4),
    sim_arguments=('--port', '{port}', '--password', '{password}', '--precalibrated',
                   '--discovery-port', '0'),
    node_parameters={'host': '127.0.0.1', 'port': '{port}', 'password_file': '{password_file}',
                     'discovery_bind': '127.0.0.1', 'joint_names': list(JOINTS),
                     'motor_addresses': [2, 3, 1], **sim_rig_parameters()},
    password='kos-sim-secret',
    link_parameters=('transport', 'host', 'port'),
    launch_sim_arguments=('--port', '5520', '--precalibrated'),
    sim_handle='kessler_kos_driver.sim_handle:KesslerSimHandle',
    refused_requests='kessler_kos_driver.refused_requests:refused_requests',
    probe='kessler_kos_driver.probe:probe',
    demo=DemoSettings(
        jog_joint='pan', jog_velocity=0.5,
        scan={'pattern': 'sector', 'pan_min': -1.0, 'pan_max': 1.0, 'speed': 1.0},
        extra_steps=(('playback', 'kessler_kos_driver.demo_steps:playback'),)),
    soak=SoakSettings(
        joint_ranges={'pan': (-2.5, 2.5), 'tilt': (-1.2, 1.2), 'slider': (0.1, 1.4)},
        extra_services={'take_picture': 'std_srvs/srv/Trigger',
                        'stop_playback': 'std_srvs/srv/Trigger',
                        'load_trajectory': 'gimbal_msgs/srv/LoadTrajectory'}),
    # the generic benchmark plus the kOS codec (bench/bench_kessler_kos.py). rad on 'pan':
    # 500 commands 1 mrad apart from 0.2 rad (inside -pi..pi); the device's Float32 target
    # (~50 rotations, 100/2pi rotations per rad) rounds by ~2e-7 rad, far below 1e-5.
    bench=BenchSettings(module='kessler_kos', stream_joint='pan', stream_base=0.2,
                        stream_tolerance=1e-5, move_targets=(-1.0, 1.0)),
)
