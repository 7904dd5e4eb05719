"""The conformance test of ros2_control's topic interface: the package's own
``<ros2_control>`` example drives the node as joint_state_topic_hardware_interface would.
Mixed into :class:`~gimbal_driver_testing.conformance.DriverConformance` (split for
size); the stand-in and the sources it follows are in
:mod:`gimbal_driver_testing.topic_system`.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from ament_index_python.packages import get_package_share_directory
from sensor_msgs.msg import JointState

from gimbal_driver_common.command_stream import GAP_TEXT
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance_rig import (
    REJECTED,
    ConformanceHelpers,
    ConformanceRig,
)
from gimbal_driver_testing.ros import joint_positions
from gimbal_driver_testing.topic_system import (
    PLUGIN,
    TopicSystemConfig,
    TopicSystemStandIn,
    rest_to_rest,
)

#: seconds of each phase at the update rate (100 Hz)
NAN_PHASE_S = 0.5
TRAJECTORY_S = 1.5
JOG_PHASE_S = 1.5
#: a pause this long on either side (the stand-in's publishes, the node's joint_states)
#: means a machine starved of CPU: the dead-man watchdog (0.5 s) may rightly have fired
STALL_S = 0.2
JOG_ATTEMPTS = 4


def delivery_gaps(log: str) -> list[float]:
    """The gaps (s) the node's delivery-gap warnings in ``log`` name (command_stream)."""
    return [float(seconds) for seconds in re.findall(rf'{GAP_TEXT} ([0-9.]+) s', log)]


class TopicInterfaceConformance(ConformanceHelpers):
    """ros2_control's topic interface against the node (attributes: see DriverConformance)."""

    small_move: dict[str, float]
    jog: tuple[str, float]
    joints: tuple[str, ...]
    answer_parameters: tuple[str, ...]

    def ros2_control_example(self) -> TopicSystemConfig:
        """The package's installed example block, config/<package>.ros2_control.xacro."""
        path = Path(get_package_share_directory(self.package), 'config',
                    f'{self.package}.ros2_control.xacro')
        return TopicSystemConfig.from_xml(path.read_text())

    @pytest.mark.ros
    def test_ros2_control_topic_interface_drives_the_node(
            self, conformance_rig: ConformanceRig) -> None:
        """The node in the example's namespace (its remapping), driven through the block's
        topics the way write() publishes: NaN before the controllers start, one controller,
        a 100 Hz trajectory with the threshold rule, then velocity interfaces with
        threshold -1. Checked on the simulator's receive side and where the joints end."""
        rig, config = conformance_rig, self.ros2_control_example()
        namespace = self.spec.namespace
        assert config.plugin == PLUGIN
        assert config.joint_states_topic == f'{namespace}/joint_states' != '/joint_states'
        # every command must take effect: none refused for an answer a loaded machine
        # delivered after the driver's default timeout
        rig.start_node(*self.answer_parameters, namespace=namespace)
        ros, names = rig.ros, config.joint_names
        stand_in = TopicSystemStandIn(ros.node, config)
        wait_for(stand_in.subscribed, 20.0, f'the node on {config.joint_commands_topic}')
        wait_for(lambda: stand_in.states_received, 20.0,
                 f'joint_states on {config.joint_states_topic} (SensorDataQoS)')
        counted, logged = self.rejections(ros), len(rig.node.output())
        before = rig.sim.motion_received()

        # controllers not started: every command NaN, published every cycle, nothing moves
        stand_in.run(NAN_PHASE_S, lambda t: {})
        assert len(stand_in.published) == stand_in.cycles > 0
        assert all(math.isnan(p) for msg in stand_in.published for p in msg.position)
        assert rig.sim.motion_received() == before
        start = {joint: stand_in.state(joint) for joint in names}

        # one controller started: its joint moves, the NaN joints are left alone
        first = next(iter(self.small_move))
        goal = start[first] + (0.1 if start[first] <= self.small_move[first] else -0.1)
        stand_in.run(TRAJECTORY_S, lambda t: {
            first: rest_to_rest(start[first], goal, TRAJECTORY_S, t)})
        self.wait_states(ros, namespace, {first: goal})
        for joint in names:
            if joint != first:
                assert stand_in.state(joint) == pytest.approx(start[joint], abs=self.tolerance)
        assert rig.sim.motion_received() != before

        # every controller: hold where the joints are, the trajectory, hold the goal (the
        # threshold rule skips cycles once the device reports the command)
        hold = {joint: stand_in.state(joint) for joint in names}
        target = {joint: self.small_move.get(joint, hold[joint]) for joint in names}
        stand_in.run(0.2, lambda t: hold)
        stand_in.run(TRAJECTORY_S, lambda t: {
            joint: rest_to_rest(hold[joint], target[joint], TRAJECTORY_S, t) for joint in names})
        stand_in.run(0.5, lambda t: target)
        self.wait_states(ros, namespace, target)
        for joint in self.small_move:
            self.wait_stopped(rig, joint, f'{joint} to stop at its goal')

        # velocity interfaces with threshold -1: every cycle is published, so the dead-man
        # watchdog (command_timeout 0.5 s) never stops the axis while the command stands.
        # A phase in which either process stalled, or the commands reached the node late
        # (the node's own delivery-gap warning), says nothing of that and runs again, the
        # other way: phases the same way add up toward the joint's limit, where it stops
        # (the turret's pitch jogs 0.3 rad a phase from 0.2 rad: past 1.047 in the third).
        joint, speed = self.jog
        stand_in.reconfigure(config.with_command_interfaces(('velocity',), -1.0))
        stalls = []
        for attempt in range(JOG_ATTEMPTS):
            window, jogging = stand_in.mark(), len(rig.node.output())
            velocity = speed if attempt % 2 == 0 else -speed
            stand_in.run(JOG_PHASE_S,
                         lambda t, v=velocity: {j: v if j == joint else 0.0 for j in names})
            moving, log = rig.sim.moving(joint), rig.node.output()[jogging:]
            stalls.append(max([stand_in.longest_gap(window), *delivery_gaps(log)]))
            if stalls[-1] < STALL_S:
                break  # an unbroken stream on both sides: the verdict counts
        else:
            pytest.fail(f'every velocity phase saw a stall (s): {stalls}')
        assert moving, f'{joint} stopped while its velocity was commanded'
        assert 'expired' not in log, log
        stand_in.run(0.3, lambda t: dict.fromkeys(names, 0.0))
        self.wait_stopped(rig, joint, f'{joint} to stop at velocity 0')

        # nothing of it was rejected or refused
        after = self.rejections(ros)
        assert (after['rejected'], after['refused']) == (counted['rejected'],
                                                         counted['refused']), (counted, after)
        assert REJECTED not in rig.node.output()[logged:]

    def wait_states(self, ros: object, namespace: str, targets: dict[str, float]) -> None:
        ros.wait_for_message(
            f'{namespace}/joint_states', JointState,
            lambda m: all(abs(joint_positions(m).get(j, math.inf) - p) <= self.tolerance
                          for j, p in targets.items()), timeout=30.0)
