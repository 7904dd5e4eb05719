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
``log_level``       ``''``                       the node's ``--ros-args --log-level`` (``debug``,
                                                 ``info``, ``warn``, ``error``, ``fatal``, or
                                                 ``logger:=level``); ``''``: not given
``host``, ``port``, ``''``                       the link's main parameters, where the node
``transport``, ...                               declares them (``DriverSpec.link_parameters``,
                                                 registry ``LINK_ARGUMENTS``); each overrides
                                                 the parameters file when given, ``''``: the
                                                 file's value
=================== ============================ ==============================================

How a given argument reaches the node, as launch_ros (jazzy) builds the command line
(launch_ros/launch_ros/actions/node.py): ``Node.__init__`` puts ``ros_arguments`` after
``--ros-args`` ahead of the ``--ros-args`` it reserves for name, namespace and parameters,
so ``log_level`` becomes ``--ros-args --log-level LEVEL``. ``Node._perform_substitutions``
turns each entry of ``parameters`` into one ``--params-file``, in list order (a dict in a
file of its own, ``_create_params_file_from_dict``, keyed with the node's full name), and rcl
applies the files in that order, a later value winning: the link arguments go in the dict
after ``params_file``, and only the given ones, so an argument not given leaves the file's
value. Dict values are typed here (an int for ``port``/``baudrate``): a plain ``str`` stays a
string (launch_ros/launch_ros/utilities/normalize_parameters.py,
``normalize_parameter_dict``: a str is ``yaml.dump``-ed, and read back as that string).

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
import re

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.substitutions import ExecutableInPackage

from gimbal_driver_common.registry import LINK_ARGUMENTS, driver_of_package

#: the boolean arguments, and what `true`/`false` may be written as (IfCondition's rule)
_TRUE, _FALSE = ('true', '1'), ('false', '0')
#: what ``--log-level`` takes (rcl/src/rcl/arguments.c ``_rcl_parse_log_level``: a
#: severity rcutils knows, case-insensitive, optionally for one logger, ``name:=severity``)
_LOG_LEVEL = re.compile(r'([\w.]+:=)?(debug|info|warn|error|fatal)', re.IGNORECASE)


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
        ('log_level', '', "the node's --ros-args --log-level (debug, info, warn, error, "
                          "fatal, or logger:=level); '' = not given"),
        *((name, '', f"{LINK_ARGUMENTS[name][1]}; overrides params_file; '' = the file's")
          for name in driver_of_package(package).link_parameters),
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


def _link_overrides(context: object, names: tuple[str, ...]) -> dict[str, object]:
    """The link arguments given (not ''), typed as the node declares them."""
    overrides: dict[str, object] = {}
    for name in names:
        text = LaunchConfiguration(name).perform(context).strip()
        if not text:
            continue
        kind = LINK_ARGUMENTS[name][0]
        try:
            overrides[name] = kind(text)
        except ValueError:
            raise ValueError(f'launch argument {name}:={text!r}: expected '
                             f'{"an integer" if kind is int else kind.__name__}') from None
    return overrides


def _log_level(context: object) -> list[str] | None:
    """``--log-level LEVEL`` for the node's ros_arguments; None when not given (an empty
    list would still add a bare ``--ros-args``: node.py ``Node.__init__``)."""
    level = LaunchConfiguration('log_level').perform(context).strip()
    if not level:
        return None
    if not _LOG_LEVEL.fullmatch(level):
        raise ValueError(f"launch argument log_level:={level!r}: expected debug, info, warn, "
                         "error, fatal or logger:=level")
    return ['--log-level', level]


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
    # later parameters entries override earlier ones (node.py _perform_substitutions)
    actions.append(LifecycleNode(
        package=package, executable=spec.node_executable, name=spec.node_name,
        namespace=namespace, output='screen', ros_arguments=_log_level(context),
        parameters=[params_file, {'autostart': _flag(context, 'autostart'),
                                  'description_file': description_file,
                                  **_link_overrides(context, spec.link_parameters)}]))
    if _flag(context, 'use_description'):
        with open(description_file, encoding='utf-8') as description:
            xml = description.read()
        actions.append(Node(
            package='robot_state_publisher', executable='robot_state_publisher',
            name='robot_state_publisher', namespace=namespace, output='screen',
            parameters=[{'robot_description': xml}]))
    return actions
