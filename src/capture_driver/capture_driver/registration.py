"""capture_driver in the driver registry (see :mod:`gimbal_driver_common.registry`).

Demo and soak values: move pan 0.4, tilt -0.2 rad (limits ±π, ±π/2); jog pan 0.3 rad/s
(max 1.5); the device's own SCN snake scan over pan ±0.2, tilt 0..0.2.
"""

from gimbal_driver_common.registry import BenchSettings, DemoSettings, DriverSpec, SoakSettings

SPEC = DriverSpec(
    name='capture',
    title='Capture Systems pan-tilt pedestal (TCP)',
    package='capture_driver',
    node_executable='capture_driver_node',
    node_name='capture_driver',
    sim_executable='capture_sim',
    node_class='capture_driver.node:CaptureDriverNode',
    description='capture_driver.urdf',
    joints=('pan', 'tilt'),
    move_goal=(0.4, -0.2),
    sim_arguments=('--port', '{port}'),
    node_parameters={'transport': 'tcp', 'host': '127.0.0.1', 'port': '{port}',
                     'status_period': 0.2, 'default_speed': 1.0, 'acceleration': 6.0},
    link_parameters=('transport', 'host', 'port', 'serial_port', 'baudrate'),
    launch_sim_arguments=('--port', '4949'),
    sim_handle='capture_driver.sim_handle:CaptureSimHandle',
    refused_requests='capture_driver.refused_requests:refused_requests',
    probe='capture_driver.probe:probe',
    demo=DemoSettings(
        jog_velocity=0.3,
        scan={'pattern': 'snake', 'pan_min': -0.2, 'pan_max': 0.2, 'tilt_min': 0.0,
              'tilt_max': 0.2, 'speed': 0.5, 'tilt_step': 0.1},
        extra_steps=(('home', ''),),
        # the simulator's answers waited for on a busy machine: MOT_Homing, a setter, is not
        # sent twice, and one answered after the default 0.5 s failed the demo's homing
        node_parameters={'request_timeout': 2.0}),
    soak=SoakSettings(extra_services={'set_stabilization': 'std_srvs/srv/SetBool',
                                      'command': 'gimbal_msgs/srv/DeviceCommand'}),
    bench=BenchSettings(module='capture'),
)
