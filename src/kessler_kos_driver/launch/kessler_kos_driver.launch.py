"""Launch the Kessler kOS driver as a managed (lifecycle) node.

ros2 launch kessler_kos_driver kessler_kos_driver.launch.py [params_file:=...] [autostart:=true]
use_description:=true also starts robot_state_publisher with urdf/kessler_kos_driver.urdf
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
    share = get_package_share_directory('kessler_kos_driver')
    default_params = os.path.join(share, 'config', 'kessler_kos_driver.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='parameter YAML (config/kessler_kos_driver*.yaml)'),
        DeclareLaunchArgument('autostart', default_value='false',
                              description='true: the node walks itself to active'),
        DeclareLaunchArgument('namespace', default_value=''),
        *description_actions('kessler_kos_driver', LaunchConfiguration('namespace')),
        LifecycleNode(
            package='kessler_kos_driver',
            executable='kessler_kos_driver_node',
            name='kessler_kos_driver',
            namespace=LaunchConfiguration('namespace'),
            output='screen',
            parameters=[LaunchConfiguration('params_file'),
                        {'autostart': LaunchConfiguration('autostart')},
                        description_parameter()],
        ),
    ])
