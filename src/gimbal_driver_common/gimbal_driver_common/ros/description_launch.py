"""The one launch description every driver package uses (full ROS 2 only).

Each driver's ``launch/<package>.launch.py`` is one line,
``driver_launch_description('<package>')``, so every driver takes the same launch arguments
(docs/interface.md, "Launch arguments"):

=================== ============================ ==============================================
argument            default                      meaning
=================== ============================ ==============================================
``params_file``     ``''``                       parameter YAML; ``''``: the package's
                                                 ``config/<package>.yaml``, or with ``sim:=true``
                                                 ``config/<package>_sim.yaml``
``autostart``       ``true``                     ``true``: the node configures and activates
                                                 itself (a bare launch ends active);
                                                 ``false``: a lifecycle manager (or
                                                 ``ros2 lifecycle set``) does
``namespace``       ``''``                       namespace of the node (and of
                                                 robot_state_publisher)
``use_description`` ``false``                    ``true``: also start robot_state_publisher with
                                                 the URDF, which turns ``joint_states`` into TF
``description_file`` the package's URDF          the URDF robot_state_publisher publishes and
                                                 ``~/look_at`` aims with (one file, so both agree)
``sim``             ``false``                    ``true``: also start the package's simulator,
                                                 serving the address the simulator YAML names
=================== ============================ ==============================================

All arguments are declared first; one OpaqueFunction after them reads them and builds the
actions. Launch executes actions in order and a LaunchConfiguration read before its
DeclareLaunchArgument has run raises ("launch configuration ... does not exist", what the
old U-Camera file did under ``ros2 launch``), so nothing here reads an argument before the
declarations. The simulator is not a ROS node (launch_ros' Node always appends
``--ros-args``, which its argument parser would refuse), so it runs as an ExecuteProcess.
Imports ``launch``/``launch_ros``: only launch files use this module.
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.substitutions import ExecutableInPackage

from gimbal_driver_common.registry import driver_of_package

#: the boolean arguments, and what `true`/`false` may be written as (IfCondition's rule)
_TRUE, _FALSE = ('true', '1'), ('false', '0')


def default_description(package: str) -> str:
    """The URDF a driver package installs: share/<package>/urdf/<package>.urdf."""
    return os.path.join(get_package_share_directory(package), 'urdf', f'{package}.urdf')


def default_params_file(package: str, sim: bool) -> str:
    """config/<package>_sim.yaml with ``sim`` (where the package has one: every driver
    here does), else config/<package>.yaml."""
    config = os.path.join(get_package_share_directory(package), 'config')
    simulator = os.path.join(config, f'{package}_sim.yaml')
    return simulator if sim and os.path.isfile(simulator) else os.path.join(
        config, f'{package}.yaml')


def driver_launch_description(package: str) -> LaunchDescription:
    """The launch arguments of docs/interface.md, then the actions they ask for."""
    arguments = [
        ('params_file', '', f"parameter YAML ('' = config/{package}.yaml, or "
                            f"config/{package}_sim.yaml with sim:=true)"),
        ('autostart', 'true', 'true: the node configures and activates itself; false: a '
                              'lifecycle manager (or ros2 lifecycle set) does'),
        ('namespace', '', 'namespace of the driver node (and of robot_state_publisher)'),
        ('use_description', 'false', 'true: also start robot_state_publisher with the URDF '
                                     '(TF for RViz)'),
        ('description_file', default_description(package),
         'URDF of the device (placeholder dimensions: measure yours); ~/look_at uses it too'),
        ('sim', 'false', "true: also start the package's simulator and connect the node to it"),
    ]
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value=default, description=description)
          for name, default, description in arguments),
        OpaqueFunction(function=_driver_actions, args=[package]),
    ])


def _flag(context: object, name: str) -> bool:
    value = LaunchConfiguration(name).perform(context).strip().lower()
    if value not in _TRUE + _FALSE:
        raise ValueError(f"launch argument {name}:={value!r}: expected 'true' or 'false'")
    return value in _TRUE


def _driver_actions(context: object, package: str) -> list[object]:
    """Run after every argument is declared: the simulator, the node, robot_state_publisher."""
    spec = driver_of_package(package)
    sim = _flag(context, 'sim')
    namespace = LaunchConfiguration('namespace').perform(context)
    params_file = (LaunchConfiguration('params_file').perform(context)
                   or default_params_file(package, sim))
    description_file = LaunchConfiguration('description_file').perform(context)
    actions: list[object] = []
    if sim:
        actions.append(ExecuteProcess(
            cmd=[ExecutableInPackage(executable=spec.sim_executable, package=package),
                 *spec.launch_sim_arguments],
            name=spec.sim_executable, output='screen'))
    actions.append(LifecycleNode(
        package=package, executable=spec.node_executable, name=spec.node_name,
        namespace=namespace, output='screen',
        parameters=[params_file, {'autostart': _flag(context, 'autostart'),
                                  'description_file': description_file}]))
    if _flag(context, 'use_description'):
        with open(description_file, encoding='utf-8') as description:
            xml = description.read()
        actions.append(Node(
            package='robot_state_publisher', executable='robot_state_publisher',
            name='robot_state_publisher', namespace=namespace, output='screen',
            parameters=[{'robot_description': xml}]))
    return actions
