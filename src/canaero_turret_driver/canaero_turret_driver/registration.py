"""canaero_turret_driver in the driver registry (see :mod:`gimbal_driver_common.registry`).

Demo and soak values: slcan over a pty; move yaw 0.4, pitch 0.2 rad (pitch -0.52..1.05);
jog yaw 0.3 rad/s (max 1.05); driver-side zigzag; joint_command targets -0.2..0.3 rad.
"""

from gimbal_driver_common.registry import BenchSettings, DemoSettings, DriverSpec, SoakSettings

SPEC = DriverSpec(
    name='canaero_turret',
    title='CANaerospace turret (slcan over a pty)',
    package='canaero_turret_driver',
    node_executable='canaero_turret_driver_node',
    node_name='canaero_turret_driver',
    sim_executable='canaero_turret_sim',
    node_class='canaero_turret_driver.node:CanaeroTurretNode',
    description='canaero_turret_driver.urdf',
    joints=('yaw', 'pitch'),
    move_goal=(0.4, 0.2),
    sim_arguments=('--link', '{link}'),
    node_parameters={'can_interface': 'slcan', 'can_channel': '{link}',
                     'can_options': ['sleep_after_open=0'], 'service_timeout': 0.3,
                     'transmission_intervals': ['yaw_position=20', 'pitch_position=20'],
                     'actuator_mode': 'auto_brake'},
    link_parameters=('can_interface', 'can_channel'),
    launch_sim_arguments=('--link', '/tmp/canaero_turret'),
    sim_handle='canaero_turret_driver.sim_handle:CanaeroSimHandle',
    refused_requests='canaero_turret_driver.refused_requests:refused_requests',
    probe='canaero_turret_driver.probe:probe',
    demo=DemoSettings(
        jog_velocity=0.3,
        scan={'pattern': 'zigzag', 'pan_min': -0.3, 'pan_max': 0.3, 'tilt_min': 0.0,
              'tilt_max': 0.2, 'speed': 0.5, 'tilt_step': 0.1},
        extra_steps=(('cover+gnss', 'canaero_turret_driver.demo_steps:cover_and_fix'),)),
    soak=SoakSettings(safe_range=(-0.2, 0.3),
                      extra_services={'set_actuator_mode': 'gimbal_msgs/srv/SetMode',
                                      'set_fan': 'std_srvs/srv/SetBool',
                                      'device_command': 'gimbal_msgs/srv/DeviceCommand'}),
    bench=BenchSettings(module='canaero_turret'),
)
