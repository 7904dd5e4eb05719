"""The checks of a driver package's device description and ros2_control example, run by each
driver package's own ``test/test_description_files.py`` (a subclass of
:class:`DescriptionSuite` naming the package) on the files it installs.

The URDF (``share/<pkg>/urdf/<description>``) loads, matches the node's default joints and
limits, and has REP-103 signs by forward kinematics: base_link -> [slider] -> pan -> tilt ->
camera_link, positive pan turns the line of sight counter-clockwise seen from above, positive
tilt raises it.

``config/<pkg>.ros2_control.xacro`` (the ``<ros2_control>`` block for
joint_state_topic_hardware_interface) and ``config/<pkg>_controllers.yaml``
(joint_state_broadcaster and a joint_trajectory_controller) are checked against the node
class's default joints and limits, against the plugin's and the controllers' own parameter
names (ros-controls/topic_based_hardware_interfaces
``joint_state_topic_hardware_interface.cpp`` ``on_init``; ros2_controllers jazzy
``joint_trajectory_controller_parameters.yaml`` and ``joint_state_broadcaster_parameters
.yaml``), and against the namespace that keeps the driver's states off /joint_states. The
controllers' file is keyed by node name (``controller_manager``, ``joint_trajectory_
controller``), as ros2_control's examples are: ros2_control_node runs in the root namespace.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, ClassVar

import pytest
import yaml

from gimbal_driver_testing.package_files import share

#: the parameters the plugin reads from <hardware> (on_init)
PLUGIN_PARAMETERS = {'joint_commands_topic', 'joint_states_topic',
                     'trigger_joint_command_threshold', 'sum_wrapped_joint_states'}
#: joint_trajectory_controller's parameters the example may set (jazzy parameter file)
JTC_PARAMETERS = {'joints', 'command_joints', 'command_interfaces', 'state_interfaces',
                  'allow_partial_joints_goal', 'interpolation_method', 'constraints',
                  'action_monitor_rate', 'open_loop_control', 'allow_integration_in_goal_'
                  'trajectories', 'set_last_command_interface_value_as_state_on_activation',
                  'interpolate_from_desired_state', 'cmd_timeout', 'gains'}


def per_joint(values: Any, count: int) -> list[float]:
    """The base node's expansion of a short default list (last value repeated)."""
    values = list(values)
    return (values + values[-1:] * count)[:count]


class DescriptionSuite:
    """Subclass with ``package = '<pkg>'`` and ``__test__ = True`` in the package's test/."""

    __test__ = False
    package: ClassVar[str] = ''

    @property
    def spec(self) -> Any:
        from gimbal_driver_common.registry import driver_of_package

        return driver_of_package(self.package)

    def node_defaults(self) -> tuple[list[str], list[float], list[float], list[float]]:
        from gimbal_driver_common.registry import resolve

        node = resolve(self.spec.node_class)
        names = list(node.DEFAULT_JOINT_NAMES)
        return (names, per_joint(node.DEFAULT_POSITION_MIN, len(names)),
                per_joint(node.DEFAULT_POSITION_MAX, len(names)),
                per_joint(node.DEFAULT_VELOCITY_MAX, len(names)))

    def description(self) -> Path:
        return share(self.package, 'urdf', self.spec.description)

    def example(self) -> str:
        return share(self.package, 'config', f'{self.package}.ros2_control.xacro').read_text()

    def test_ships_one_description_the_registered_one(self) -> None:
        assert [p.name for p in share(self.package, 'urdf').glob('*.urdf')] == [
            self.spec.description]

    def test_joints_equal_the_node_defaults(self) -> None:
        urdf = pytest.importorskip('urdf_parser_py.urdf', reason='needs urdfdom-py')
        robot = urdf.URDF.from_xml_file(str(self.description()))
        names, lower, upper, velocity = self.node_defaults()
        assert robot.get_root() == 'base_link'
        chain = robot.get_chain('base_link', 'camera_link', joints=True, links=False)
        joints = {joint.name: joint for joint in robot.joints}
        movable = [name for name in chain if joints[name].type != 'fixed']
        assert movable == names, f'{self.package}: URDF chain {movable} vs node {names}'
        for i, name in enumerate(names):
            joint = joints[name]
            assert joint.type == ('prismatic' if name == 'slider' else 'revolute')
            assert joint.limit.lower == pytest.approx(lower[i], abs=1e-12), name
            assert joint.limit.upper == pytest.approx(upper[i], abs=1e-12), name
            assert joint.limit.velocity == pytest.approx(velocity[i], abs=1e-12), name

    def test_signs_follow_rep103_by_forward_kinematics(self) -> None:
        from gimbal_driver_common.kinematics import AimingChain

        chain = AimingChain.from_file(self.description())
        pan, tilt = chain.pan_joint, chain.tilt_joint
        zero = {name: 0.0 for name in chain.movable_joints}

        def sight(**moved: float) -> Any:
            return chain.aim_pose({**zero, **moved})[:3, 0]

        assert sight() == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)  # forward (+x) at zero
        turned = sight(**{pan: 0.3})
        assert turned == pytest.approx([math.cos(0.3), math.sin(0.3), 0.0], abs=1e-12)  # left
        raised = sight(**{tilt: 0.3})
        assert raised == pytest.approx([math.cos(0.3), 0.0, math.sin(0.3)], abs=1e-12)  # up
        if 'slider' in chain.movable_joints:  # positive slider travels along the track (+x)
            start = chain.aim_pose(zero)[:3, 3]
            moved = chain.aim_pose({**zero, 'slider': 0.5})[:3, 3]
            assert list(moved - start) == pytest.approx([0.5, 0.0, 0.0], abs=1e-12)

    def test_the_ros2_control_block_names_the_nodes_joints_and_limits(self) -> None:
        from gimbal_driver_testing.topic_system import PLUGIN, TopicSystemConfig

        root = ET.fromstring(self.example())
        assert root.tag == 'robot' and root.find('ros2_control') is not None  # include-able
        config = TopicSystemConfig.from_xml(self.example())
        names, low, high, _ = self.node_defaults()
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

    def test_the_driver_states_stay_off_joint_states(self) -> None:
        """The block reads and writes the topics of the node in its namespace (the launch
        argument namespace:=..., -r __ns:=... with ros2 run): joint_state_broadcaster owns
        /joint_states."""
        from gimbal_driver_testing.topic_system import TopicSystemConfig

        config = TopicSystemConfig.from_xml(self.example())
        namespace = self.spec.namespace
        assert namespace not in ('', '/')
        assert config.joint_states_topic == f'{namespace}/joint_states'
        assert config.joint_commands_topic == f'{namespace}/joint_command'
        header = self.example().split('<robot')[0]
        assert f'namespace:={namespace.lstrip("/")}' in header
        assert f'-r __ns:={namespace}' in header

    def test_the_controllers_yaml_drives_the_blocks_joints(self) -> None:
        from gimbal_driver_testing.topic_system import TopicSystemConfig

        data = yaml.safe_load(share(self.package, 'config',
                                    f'{self.package}_controllers.yaml').read_text())
        # keyed /**/<node>: rcl applies them under any namespace (as the driver's own files)
        manager = data['/**/controller_manager']['ros__parameters']
        assert manager['update_rate'] == 100
        assert manager['joint_state_broadcaster']['type'] == \
            'joint_state_broadcaster/JointStateBroadcaster'
        assert manager['joint_trajectory_controller']['type'] == \
            'joint_trajectory_controller/JointTrajectoryController'
        jtc = data['/**/joint_trajectory_controller']['ros__parameters']
        assert set(jtc) <= JTC_PARAMETERS, set(jtc) - JTC_PARAMETERS
        config = TopicSystemConfig.from_xml(self.example())
        assert jtc['joints'] == config.joint_names == self.node_defaults()[0]
        assert jtc['command_interfaces'] == ['position']
        assert set(jtc['state_interfaces']) <= set(config.joints[0].state_interfaces)
