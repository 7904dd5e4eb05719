"""Launch the CANaerospace turret driver as a managed (lifecycle) node.

ros2 launch canaero_turret_driver canaero_turret_driver.launch.py [params_file:=...]
    [autostart:=true] [namespace:=...]
With autostart false (the default here) a lifecycle manager configures and activates it.
Bring the CAN interface up first (see the package README), e.g.
    sudo ip link set can0 type can bitrate 500000 && sudo ip link set can0 up
use_description:=true also starts robot_state_publisher with urdf/canaero_turret_driver.urdf
(or description_file:=...), which the node uses for ~/look_at too.
Uses launch/launch_ros, which a full ROS 2 install provides (not the pip environment).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode

from gimbal_driver_common.ros.description_launch import description_actions, description_parameter


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('canaero_turret_driver')
    default_params = os.path.join(share, 'config', 'canaero_turret_driver.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='parameter YAML (config/canaero_turret_driver*.yaml)'),
        DeclareLaunchArgument('autostart', default_value='false',
                              description='true: the node walks itself to active'),
        DeclareLaunchArgument('namespace', default_value=''),
        *description_actions('canaero_turret_driver', LaunchConfiguration('namespace')),
        LifecycleNode(
            package='canaero_turret_driver',
            executable='canaero_turret_driver_node',
            name='canaero_turret_driver',
            namespace=LaunchConfiguration('namespace'),
            output='screen',
            parameters=[LaunchConfiguration('params_file'),
                        {'autostart': LaunchConfiguration('autostart')},
                        description_parameter()],
        ),
    ])
