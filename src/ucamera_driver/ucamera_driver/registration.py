"""ucamera_driver in the driver registry (see :mod:`gimbal_driver_common.registry`).

Demo and soak values: UCSP over a pty; move pan 0.4, tilt -0.3 rad (limits ±π, ±π/2); jog
pan 0.3 rad/s (max 1.0); driver-side sector; then zoom and the pilot home.
"""

from gimbal_driver_common.registry import BenchSettings, DemoSettings, DriverSpec, SoakSettings

SPEC = DriverSpec(
    name='ucamera',
    title='Airelectronics U-Camera (UCSP over a pty)',
    package='ucamera_driver',
    node_executable='ucamera_driver_node',
    node_name='ucamera_driver',
    sim_executable='ucamera_sim',
    node_class='ucamera_driver.node:UCameraDriverNode',
    description='ucamera_driver.urdf',
    joints=('pan', 'tilt'),
    move_goal=(0.4, -0.3),
    sim_arguments=('--link', '{link}'),
    node_parameters={'serial_port': '{link}', 'telemetry_rate': 50, 'gps_feed': 'external'},
    link_parameters=('serial_port', 'baudrate'),
    launch_sim_arguments=('--link', '/tmp/ucamera_sim_tty'),
    sim_handle='ucamera_driver.sim_handle:UCameraSimHandle',
    refused_requests='ucamera_driver.refused_requests:refused_requests',
    probe='ucamera_driver.probe:probe',
    demo=DemoSettings(
        jog_velocity=0.3,
        scan={'pattern': 'sector', 'pan_min': -0.3, 'pan_max': 0.3, 'speed': 0.5},
        extra_steps=(('zoom', 'ucamera_driver.demo_steps:zoom'), ('home', ''))),
    soak=SoakSettings(extra_services={'set_mode': 'gimbal_msgs/srv/SetMode',
                                      'save_configuration': 'std_srvs/srv/Trigger',
                                      'save_ffc': 'std_srvs/srv/Trigger'}),
    # the generic benchmark plus the UCSP codec (bench/bench_ucamera.py); the wire carries
    # deg*100 (0.01 deg = 1.75e-4 rad)
    bench=BenchSettings(module='ucamera', stream_joint='tilt', stream_tolerance=1e-4),
)
