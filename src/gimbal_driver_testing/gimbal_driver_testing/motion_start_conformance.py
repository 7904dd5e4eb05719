"""The motion-start part of the conformance suite: a command the device ACKs and ignores
is reported (diagnostics WARN with target and position, one log line, a running goal ends
with the reason), the WARN stays on /diagnostics after the stop that ends the goal until the
next motion command for the axis, and a slow but moving axis is not reported.

The simulators' shared fault ``ignore_motion on`` (:mod:`gimbal_driver_common.sim_control`)
makes the device accept moves and jogs and drop them, as a drive in a mode that ignores
positions does.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_testing.conformance_rig import (
    ConformanceHelpers,
    ConformanceRig,
    GoalStatus,
)
from gimbal_driver_testing.ros import joint_positions

STALLED = 'commanded but not moving'
WARN = 1
#: motion_start_timeout in these tests (s): short, so the suite does not wait the default
TEST_TIMEOUT = 0.5


class MotionStartConformance(ConformanceHelpers):
    """Mixed into :class:`~gimbal_driver_testing.conformance.DriverConformance`."""

    small_move: dict[str, float]

    @contextmanager
    def motion_start_timeout(self, rig: ConformanceRig, seconds: float) -> Iterator[None]:
        default = rig.ros.get_parameter(self.node_name, 'motion_start_timeout')
        assert rig.ros.set_parameter(self.node_name, 'motion_start_timeout', seconds).successful
        try:
            yield
        finally:
            assert rig.ros.set_parameter(self.node_name, 'motion_start_timeout',
                                         default).successful

    @contextmanager
    def ignoring_motion(self, rig: ConformanceRig, joint: str) -> Iterator[None]:
        """The device ignores motion commands; afterwards ``joint`` is stopped and its WARN
        (which a stop leaves shown) cleared by a new command: to where it is."""
        rig.sim.control('ignore_motion on')
        try:
            yield
        finally:
            rig.sim.control('ignore_motion off')
            rig.ros.call(Trigger, self.srv('stop'), Trigger.Request())
            here = joint_positions(rig.ros.wait_for_message('joint_states', JointState))[joint]
            rig.ros.publish('joint_command', JointState(name=[joint], position=[here]))
            self.wait_not_stalled(rig, joint)

    def wait_not_stalled(self, rig: ConformanceRig, joint: str) -> None:
        rig.ros.wait_for_diagnostic(self.node_name, joint,
                                    lambda s: STALLED not in s.message, timeout=30)

    def wait_stalled(self, rig: ConformanceRig, joint: str) -> DiagnosticStatus:
        """A /diagnostics status published from now on that shows the axis WARN."""
        status = rig.ros.wait_for_diagnostic(self.node_name, joint,
                                             lambda s: STALLED in s.message, timeout=30)
        assert status.level[0] == WARN, status
        return status

    def away_target(self, rig: ConformanceRig) -> tuple[str, float]:
        """A safe target of the first small-move joint, well away from where it is."""
        joint, safe = next(iter(self.small_move.items()))
        current = joint_positions(rig.ros.wait_for_message('joint_states', JointState))[joint]
        if abs(current - safe) > 0.05:
            return joint, safe
        return joint, safe + (0.1 if safe <= 0 else -0.1)

    @pytest.mark.ros
    def test_an_ignored_move_to_goal_ends_with_the_reason(self, rig: ConformanceRig) -> None:
        joint, target = self.away_target(rig)
        with self.motion_start_timeout(rig, TEST_TIMEOUT), self.ignoring_motion(rig, joint):
            # move_timeout stays at its default: only the motion watch ends this goal soon
            result, status, _ = self.move_to(rig.ros, {joint: target})
            assert status == GoalStatus.STATUS_ABORTED and not result.success, result.message
            assert f'{joint}: {STALLED} (target {target:.4f}' in result.message, result.message
            # the goal stopped the axis; the WARN is on /diagnostics after that stop
            values = {kv.key: kv.value for kv in self.wait_stalled(rig, joint).values}
            assert values['commanded'] == f'{target:.4f}', values
            # ... until the next motion command for that axis (the device obeys it now)
            rig.sim.control('ignore_motion off')
            result, status, _ = self.move_to(rig.ros, {joint: target})
            assert result.success, result.message
            self.wait_not_stalled(rig, joint)

    @pytest.mark.ros
    def test_an_ignored_joint_command_warns_on_the_axis_once(self, rig: ConformanceRig) -> None:
        joint, target = self.away_target(rig)
        logged = len(rig.node.output())
        with self.motion_start_timeout(rig, TEST_TIMEOUT), self.ignoring_motion(rig, joint):
            for _ in range(3):   # the same unmet command again: still one episode
                rig.ros.publish('joint_command', JointState(name=[joint], position=[target]))
                status = self.wait_stalled(rig, joint)
            values = {kv.key: kv.value for kv in status.values}
            assert values['commanded'] == f'{target:.4f}', values
            assert 'position' in values
            rig.node.wait_for_output(STALLED)
            lines = [line for line in rig.node.output()[logged:].splitlines()
                     if STALLED in line]
            assert len(lines) == 1, lines
            stop = rig.ros.call(Trigger, self.srv('stop'), Trigger.Request())
            assert stop.success, stop.message
            # a stop leaves the warning shown; the next command for the axis clears it
            self.wait_stalled(rig, joint)
            rig.sim.control('ignore_motion off')
            rig.ros.publish('joint_command', JointState(name=[joint], position=[target]))
            self.wait_not_stalled(rig, joint)

    @pytest.mark.ros
    def test_a_slow_move_is_not_reported(self, rig: ConformanceRig) -> None:
        joint, position, speed = self.far_move
        logged = len(rig.node.output())
        with self.motion_start_timeout(rig, TEST_TIMEOUT):
            # several motion_start_timeouts of a slow move, then cancelled: had the watch
            # taken it for a stall, the goal would have ended ABORTED with that reason
            result, status, _ = self.move_to(rig.ros, {joint: position}, [speed],
                                             cancel_after=6 * TEST_TIMEOUT)
        assert status == GoalStatus.STATUS_CANCELED, (status, result.message)
        assert STALLED not in rig.node.output()[logged:]
        self.wait_stopped(rig, joint, 'the cancelled slow move to stop')
