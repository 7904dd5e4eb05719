"""The reference virtual gimbal in the driver registry (gimbal_driver_common.registry)."""

from gimbal_driver_common.registry import BenchSettings, DemoSettings, DriverSpec

SPEC = DriverSpec(
    name='virtual_gimbal',
    title='virtual gimbal (reference)',
    package='virtual_gimbal_driver',
    node_executable='virtual_gimbal_driver_node',
    node_name='virtual_gimbal_driver',
    sim_executable='virtual_gimbal_sim',
    node_class='virtual_gimbal_driver.node:VirtualGimbalNode',
    description='virtual_gimbal_driver.urdf',
    joints=('pan', 'tilt'),
    move_goal=(0.4, -0.2),
    sim_arguments=('--port', '{port}'),
    node_parameters={'host': '127.0.0.1', 'port': '{port}'},
    link_parameters=('host', 'port'),
    launch_sim_arguments=('--port', '4950'),
    sim_handle='virtual_gimbal_driver.sim_handle:VirtualGimbalSim',
    probe='virtual_gimbal_driver.probe:probe',
    demo=DemoSettings(scan={'pattern': 'sector', 'pan_min': -0.3, 'pan_max': 0.3,
                            'speed': 0.6}),
    bench=BenchSettings(stream_joint='pan', max_rate=200.0),
)
