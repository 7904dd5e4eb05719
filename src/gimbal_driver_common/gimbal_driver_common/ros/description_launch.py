"""Launch actions that publish a driver's URDF with robot_state_publisher (full ROS only).

Every driver launch file adds :func:`description_actions`: the arguments
``use_description`` (default false) and ``description_file`` (default: the package's
installed ``urdf/<package>.urdf``) and, when ``use_description:=true``, a
robot_state_publisher in the driver's namespace, which turns the driver's
``joint_states`` into TF frames for RViz. The driver node gets the same file as its
``description_file`` parameter (see :func:`description_parameter`), so ``~/look_at`` and
TF always agree. Imports ``launch``/``launch_ros``: only launch files use this module.
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node


def default_description(package: str) -> str:
    """The URDF a driver package installs: share/<package>/urdf/<package>.urdf."""
    return os.path.join(get_package_share_directory(package), 'urdf', f'{package}.urdf')


def description_parameter() -> dict[str, object]:
    """The driver node's ``description_file`` parameter, from the launch argument."""
    return {'description_file': LaunchConfiguration('description_file')}


def description_actions(package: str, namespace: object = '') -> list[object]:
    """Launch arguments and the optional robot_state_publisher for ``package``."""

    def state_publisher(context: object) -> list[object]:
        if LaunchConfiguration('use_description').perform(context).lower() != 'true':
            return []
        path = LaunchConfiguration('description_file').perform(context)
        with open(path, encoding='utf-8') as description:
            xml = description.read()
        return [Node(
            package='robot_state_publisher', executable='robot_state_publisher',
            name='robot_state_publisher', namespace=namespace, output='screen',
            parameters=[{'robot_description': xml}],
        )]

    return [
        DeclareLaunchArgument(
            'use_description', default_value='false',
            description='true: also start robot_state_publisher with the URDF (TF for RViz)'),
        DeclareLaunchArgument(
            'description_file', default_value=default_description(package),
            description='URDF of the device (placeholder dimensions: measure yours)'),
        OpaqueFunction(function=state_publisher),
    ]


def driver_launch_description(package: str) -> LaunchDescription:
    """The standard launch of a driver: its lifecycle node ``<package>_node`` named ``<package>``.

    Arguments: ``params_file`` (default share/<package>/config/<package>.yaml),
    ``autostart`` (default false: a lifecycle manager configures and activates it),
    ``namespace``, and the description arguments of :func:`description_actions`.
    """
    share = get_package_share_directory(package)
    namespace = LaunchConfiguration('namespace')
    return LaunchDescription([
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(share, 'config', f'{package}.yaml'),
                              description=f'parameter YAML (config/{package}*.yaml)'),
        DeclareLaunchArgument('autostart', default_value='false',
                              description='true: the node walks itself to active'),
        DeclareLaunchArgument('namespace', default_value=''),
        *description_actions(package, namespace),
        LifecycleNode(
            package=package, executable=f'{package}_node', name=package,
            namespace=namespace, output='screen',
            parameters=[LaunchConfiguration('params_file'),
                        {'autostart': LaunchConfiguration('autostart')},
                        description_parameter()],
        ),
    ])
