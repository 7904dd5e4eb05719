"""Every driver's ros2_control example names the node's joints and limits.

``config/<package>.ros2_control.xacro`` (the ``<ros2_control>`` block for
joint_state_topic_hardware_interface) and ``config/<package>_controllers.yaml``
(joint_state_broadcaster and a joint_trajectory_controller) are parsed and checked against
the node class's default joints and limits (what the node uses without parameters, and what
its URDF says, see test_descriptions.py), against the plugin's and the controllers' own
parameter names (ros-controls/topic_based_hardware_interfaces
``joint_state_topic_hardware_interface.cpp`` ``on_init``; ros2_controllers jazzy
``joint_trajectory_controller_parameters.yaml`` and ``joint_state_broadcaster_parameters
.yaml``), and against the namespace that keeps the driver's states off /joint_states. The
block drives each node in the conformance suite (``test_ros2_control_topic_interface``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

pytest.importorskip('rclpy', reason='the node classes need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='the node classes need the built workspace')

from gimbal_driver_common.registry import DriverSpec, drivers, resolve
from gimbal_driver_common.testing.topic_system import PLUGIN, TopicSystemConfig

SRC = Path(__file__).resolve().parent.parent / 'src'
SPECS: dict[str, DriverSpec] = {spec.package: spec for spec in drivers()}
#: the parameters the plugin reads from <hardware> (on_init)
PLUGIN_PARAMETERS = {'joint_commands_topic', 'joint_states_topic',
                     'trigger_joint_command_threshold', 'sum_wrapped_joint_states'}
#: joint_trajectory_controller's parameters the example may set (jazzy parameter file)
JTC_PARAMETERS = {'joints', 'command_joints', 'command_interfaces', 'state_interfaces',
                  'allow_partial_joints_goal', 'interpolation_method', 'constraints',
                  'action_monitor_rate', 'open_loop_control', 'allow_integration_in_goal_'
                  'trajectories', 'set_last_command_interface_value_as_state_on_activation',
                  'interpolate_from_desired_state', 'cmd_timeout', 'gains'}


def per_joint(values, count: int) -> list[float]:
    """The base node's expansion of a short default list (last value repeated)."""
    values = list(values)
    return (values + values[-1:] * count)[:count]


def example(pkg: str) -> str:
    return (SRC / pkg / 'config' / f'{pkg}.ros2_control.xacro').read_text()


def controllers(pkg: str) -> dict:
    return yaml.safe_load((SRC / pkg / 'config' / f'{pkg}_controllers.yaml').read_text())


def defaults(pkg: str) -> tuple[list[str], list[float], list[float]]:
    node = resolve(SPECS[pkg].node_class)
    names = list(node.DEFAULT_JOINT_NAMES)
    return (names, per_joint(node.DEFAULT_POSITION_MIN, len(names)),
            per_joint(node.DEFAULT_POSITION_MAX, len(names)))


@pytest.mark.parametrize('pkg', list(SPECS))
def test_the_block_names_the_nodes_joints_and_limits(pkg: str) -> None:
    root = ET.fromstring(example(pkg))
    assert root.tag == 'robot' and root.find('ros2_control') is not None  # xacro:include-able
    config = TopicSystemConfig.from_xml(example(pkg))
    names, low, high = defaults(pkg)
    assert config.plugin == PLUGIN
    assert config.joint_names == names
    for joint, minimum, maximum in zip(config.joints, low, high, strict=True):
        assert joint.command_interfaces == ('position',), joint.name  # a speed limit only
        assert joint.limits['position'] == (pytest.approx(minimum, abs=1e-12),
                                             pytest.approx(maximum, abs=1e-12)), joint.name
        assert set(joint.state_interfaces) == {'position', 'velocity'}, joint.name
    hardware = root.find('ros2_control/hardware')
    given = {param.get('name') for param in hardware.findall('param')}
    assert given <= PLUGIN_PARAMETERS, given - PLUGIN_PARAMETERS
    assert config.threshold == 1e-5  # the plugin's default, written out


@pytest.mark.parametrize('pkg', list(SPECS))
def test_the_driver_states_stay_off_joint_states(pkg: str) -> None:
    """The block reads and writes the topics of the node in its namespace (the launch
    argument namespace:=..., -r __ns:=... with ros2 run): joint_state_broadcaster owns
    /joint_states."""
    config = TopicSystemConfig.from_xml(example(pkg))
    namespace = SPECS[pkg].namespace
    assert namespace not in ('', '/')
    assert config.joint_states_topic == f'{namespace}/joint_states'
    assert config.joint_commands_topic == f'{namespace}/joint_command'
    header = example(pkg).split('<robot')[0]
    assert f'namespace:={namespace.lstrip("/")}' in header
    assert f'-r __ns:={namespace}' in header


@pytest.mark.parametrize('pkg', list(SPECS))
def test_the_controllers_yaml_drives_the_blocks_joints(pkg: str) -> None:
    data = controllers(pkg)
    manager = data['controller_manager']['ros__parameters']
    assert manager['update_rate'] == 100
    assert manager['joint_state_broadcaster']['type'] == \
        'joint_state_broadcaster/JointStateBroadcaster'
    assert manager['joint_trajectory_controller']['type'] == \
        'joint_trajectory_controller/JointTrajectoryController'
    jtc = data['joint_trajectory_controller']['ros__parameters']
    assert set(jtc) <= JTC_PARAMETERS, set(jtc) - JTC_PARAMETERS
    config = TopicSystemConfig.from_xml(example(pkg))
    assert jtc['joints'] == config.joint_names == defaults(pkg)[0]
    assert jtc['command_interfaces'] == ['position']
    assert set(jtc['state_interfaces']) <= set(config.joints[0].state_interfaces)
