"""The ros2_control topic-interface stand-in replays the plugin's read()/write() rules
(joint_state_topic_hardware_interface.cpp), in-process; the conformance suite drives every
node with it."""

from __future__ import annotations

import math

import pytest

pytest.importorskip('rclpy', reason='the stand-in builds sensor_msgs/JointState')
from sensor_msgs.msg import JointState

from gimbal_driver_testing.topic_system import (
    DEFAULT_THRESHOLD,
    PLUGIN,
    TopicSystem,
    TopicSystemConfig,
    rest_to_rest,
    rest_to_rest_peak_speed,
)

BLOCK = f"""<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <ros2_control name="rig" type="system">
    <hardware>
      <plugin>{PLUGIN}</plugin>
      <param name="joint_commands_topic">/rig/joint_command</param>
    </hardware>
    <joint name="pan">
      <command_interface name="position"><param name="min">-3</param>
        <param name="max">3</param></command_interface>
      <state_interface name="position"/>
      <state_interface name="velocity"/>
    </joint>
    <joint name="tilt">
      <command_interface name="position"/>
      <state_interface name="position"/>
      <state_interface name="velocity"/>
    </joint>
  </ros2_control>
</robot>"""


def test_the_block_is_read_with_the_plugins_defaults() -> None:
    config = TopicSystemConfig.from_xml(BLOCK)
    assert (config.name, config.plugin) == ('rig', PLUGIN)
    assert config.joint_commands_topic == '/rig/joint_command'
    assert config.joint_states_topic == '/robot_joint_states'  # on_init's default
    assert config.threshold == DEFAULT_THRESHOLD == 1e-5
    assert config.joint_names == ['pan', 'tilt']
    assert config.joints[0].limits == {'position': (-3.0, 3.0)}
    assert config.joints[1].limits == {'position': (None, None)}


def test_nan_commands_are_published_every_cycle() -> None:
    system = TopicSystem(TopicSystemConfig.from_xml(BLOCK))
    system.read(JointState(name=['pan', 'tilt'], position=[0.1, 0.2], velocity=[0.0, 0.0]))
    for _ in range(3):
        msg = system.write()  # |state - NaN| is NaN, and NaN <= threshold is false
        assert list(msg.name) == ['pan', 'tilt'] and all(map(math.isnan, msg.position))
        assert not msg.velocity and not msg.effort


def test_a_cycle_is_skipped_while_the_states_match_the_commands() -> None:
    system = TopicSystem(TopicSystemConfig.from_xml(BLOCK))
    system.read(JointState(name=['pan', 'tilt'], position=[0.1, 0.2]))
    system.commands.update({('pan', 'position'): 0.1, ('tilt', 'position'): 0.2 + 5e-6})
    assert system.write() is None  # sum of |state - command| 5e-6 <= 1e-5
    system.commands[('pan', 'position')] = 0.1 + 6e-6
    assert list(system.write().position) == [0.1 + 6e-6, 0.2 + 5e-6]  # 1.1e-5 > 1e-5
    # read() takes finite values of this block's joints only
    system.read(JointState(name=['tilt', 'roll'], position=[math.nan, 9.0]))
    assert system.states[('tilt', 'position')] == 0.2 and ('roll', 'position') not in \
        system.states


def test_velocity_interfaces_need_threshold_minus_one() -> None:
    """With velocity command interfaces, a jog whose velocity the device reports back is
    below the default threshold: write() stops publishing and the node's dead-man watchdog
    stops the axis. Threshold -1 publishes every cycle."""
    config = TopicSystemConfig.from_xml(BLOCK)
    default = TopicSystem(config.with_command_interfaces(('velocity',), DEFAULT_THRESHOLD))
    always = TopicSystem(config.with_command_interfaces(('velocity',), -1.0))
    for system in (default, always):
        system.read(JointState(name=['pan', 'tilt'], position=[0.0, 0.0], velocity=[0.3, 0.0]))
        system.commands.update({('pan', 'velocity'): 0.3, ('tilt', 'velocity'): 0.0})
    assert default.write() is None
    msg = always.write()
    assert list(msg.velocity) == [0.3, 0.0] and not msg.position


def test_a_joint_with_position_and_velocity_appends_both() -> None:
    config = TopicSystemConfig.from_xml(BLOCK).with_command_interfaces(
        ('position', 'velocity'), -1.0)
    system = TopicSystem(config)
    system.commands.update({('pan', 'position'): 1.0, ('pan', 'velocity'): 0.5,
                            ('tilt', 'position'): 2.0, ('tilt', 'velocity'): 0.0})
    msg = system.write()
    assert list(msg.position) == [1.0, 2.0] and list(msg.velocity) == [0.5, 0.0]


def test_the_trajectory_is_a_rest_to_rest_quintic() -> None:
    assert rest_to_rest(0.0, 0.5, 2.0, -1.0) == 0.0
    assert rest_to_rest(0.0, 0.5, 2.0, 1.0) == pytest.approx(0.25)
    assert rest_to_rest(0.0, 0.5, 2.0, 3.0) == 0.5
    dt = 1e-6
    speed = (rest_to_rest(0.0, 0.5, 2.0, 1.0 + dt) - rest_to_rest(0.0, 0.5, 2.0, 1.0)) / dt
    assert speed == pytest.approx(rest_to_rest_peak_speed(0.0, 0.5, 2.0), rel=1e-4)
    start_speed = rest_to_rest(0.0, 0.5, 2.0, dt) / dt
    assert start_speed == pytest.approx(0.0, abs=1e-6)
