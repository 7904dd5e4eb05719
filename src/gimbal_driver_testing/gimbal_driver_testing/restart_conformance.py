"""The conformance tests that restart, signal or break the node: lifecycle, presets across
a restart, link drop, signals and start-up parameters. Mixed into
:class:`~gimbal_driver_testing.conformance.DriverConformance` (split for size).
"""

from __future__ import annotations

import signal
from concurrent.futures import ThreadPoolExecutor

import pytest
from action_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import Transition
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_testing import DomainLease, ManagedProcess, wait_for
from gimbal_driver_testing.conformance_rig import (
    ERROR,
    OK,
    STALE,
    ConformanceHelpers,
    ConformanceRig,
)
from gimbal_msgs.msg import GimbalStatus
from gimbal_msgs.srv import ClearPreset, GotoPreset, ListPresets, SetPreset

#: s the simulator refuses the node after a link drop, at most: the test ends the outage
#: itself once it has seen what a link down must show
LINK_DOWN_UNTIL_CHECKED_S = 60.0


class RestartConformance(ConformanceHelpers):
    """Tests that start their own node (see DriverConformance for the attributes)."""

    @pytest.mark.ros
    def test_presets_persist_across_a_node_restart(self, rig: ConformanceRig) -> None:
        index = self.preset_index + 2
        reply = rig.ros.call(SetPreset, self.srv('set_preset'), SetPreset.Request(
            index=index, name='kept', joint_names=list(self.small_move),
            positions=list(self.small_move.values())))
        assert reply.success, reply.message
        rig.start_node()
        try:
            listed = rig.ros.call(ListPresets, self.srv('list_presets'), ListPresets.Request())
            assert listed.success, listed.message
            kept = {p.index: p for p in listed.presets}
            assert index in kept, listed.presets
            assert list(kept[index].positions) == pytest.approx(
                list(self.small_move.values()), abs=1e-3)
            go = rig.ros.call(GotoPreset, self.srv('goto_preset'),
                              GotoPreset.Request(index=index))
            assert go.success, go.message
            self.wait_positions(rig.ros, self.small_move)
        finally:
            rig.ros.call(ClearPreset, self.srv('clear_preset'), ClearPreset.Request(index=index))

    @pytest.mark.ros
    def test_lifecycle_configure_activate_deactivate_cleanup(
            self, conformance_rig: ConformanceRig) -> None:
        rig, name = conformance_rig, self.node_name
        rig.start_node('autostart:=false', wait_active=False)
        ros = rig.ros
        ros.wait_for_lifecycle_state(name, 'unconfigured')
        assert ros.lifecycle_transition(name, Transition.TRANSITION_CONFIGURE)
        assert ros.lifecycle_state(name) == 'inactive'
        reply = ros.call(Trigger, self.srv('reset_faults'), Trigger.Request())
        assert not reply.success and 'not active' in reply.message, reply.message
        before = rig.sim.motion_received()
        result, _, _ = self.move_to(ros, self.small_move)
        assert not result.success and 'not active' in result.message, result.message
        # a joint_command is refused too, and counted by its reason
        key = 'refused: node not active'
        counted = self.rejections(ros).get(key, 0)
        ros.publish('joint_command', JointState(name=list(self.small_move),
                                                position=list(self.small_move.values())))
        self.rejections(ros, lambda counts: counts.get(key, 0) > counted)
        assert rig.sim.motion_received() == before
        assert ros.lifecycle_transition(name, Transition.TRANSITION_ACTIVATE)
        assert ros.lifecycle_state(name) == 'active'
        ros.wait_for_message('joint_states', JointState, timeout=30)
        self.start_far_move(rig)
        assert ros.lifecycle_transition(name, Transition.TRANSITION_DEACTIVATE)
        self.wait_stopped(rig, self.far_move[0], 'deactivate to stop the axis')
        assert ros.lifecycle_state(name) == 'inactive'
        assert ros.lifecycle_transition(name, Transition.TRANSITION_CLEANUP)
        assert ros.lifecycle_state(name) == 'unconfigured'
        assert ros.lifecycle_transition(name, Transition.TRANSITION_CONFIGURE)
        assert ros.lifecycle_transition(name, Transition.TRANSITION_ACTIVATE)
        assert self.move_to(ros, self.small_move)[0].success

    @pytest.mark.ros
    def test_link_drop_is_an_error_then_reconnects_and_obeys(self, rig: ConformanceRig) -> None:
        ros = rig.ros
        self.wait_connection(ros, OK)
        # ~/status is published only while subscribed: record it from before the drop, so
        # a reconnect that comes quickly cannot hide the disconnected messages
        statuses = ros.subscribe(self.srv('status'), GimbalStatus)
        wait_for(lambda: statuses, 15.0, 'a first ~/status')
        # /diagnostics too: the link may be back (2 s) before the refused command below is
        # counted, and the STALE joints were published while it was down
        diagnostics = ros.subscribe('/diagnostics', DiagnosticArray)
        dropped_at = len(diagnostics)
        # down until the refusal below is counted (``drop 0`` then ends it: cut again, back
        # at once), not for a fixed time that a slow run can miss whole
        rig.sim.drop_link(LINK_DOWN_UNTIL_CHECKED_S)
        status = self.wait_connection(ros, ERROR, since=dropped_at)
        assert self.link_lost_text in status.message, status.message
        # a joint_command while the link is down is refused and counted by its reason
        key = 'refused: device not connected'
        counted = self.rejections(ros).get(key, 0)
        command = JointState(name=list(self.small_move), position=list(self.small_move.values()))

        def refused_while_down() -> bool:
            ros.publish('joint_command', command)
            return self.rejections(ros).get(key, 0) > counted

        wait_for(refused_while_down, 20.0, 'a joint_command refused while disconnected')
        # the axes' last values are stale, and ~/status says the link is down
        ros.wait_for_diagnostic(self.node_name, self.joints[0], lambda s: s.level[0] == STALE,
                                since=dropped_at)
        wait_for(lambda: any(m.connection != GimbalStatus.CONNECTION_CONNECTED
                             for m in list(statuses)), 15.0, 'a ~/status saying the link is down')
        rig.sim.drop_link(0.0)  # the link comes back
        status = self.wait_connection(ros, OK, timeout=40)
        assert int({kv.key: kv.value for kv in status.values}['reconnects']) >= 1
        ros.wait_for_message(self.srv('status'), GimbalStatus,
                             lambda m: m.connection == GimbalStatus.CONNECTION_CONNECTED
                             and m.reconnects >= 1)
        rig.node.wait_for_output('reconnected')
        ros.wait_for_message('joint_states', JointState, timeout=20)
        away = {j: p + (0.1 if p <= 0 else -0.1) for j, p in self.small_move.items()}
        result, _, _ = self.move_to(ros, away)
        assert result.success, result.message
        self.wait_positions(ros, away)

    @pytest.mark.ros
    @pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
    def test_axes_stop_when_the_node_gets_a_signal(
            self, conformance_rig: ConformanceRig, sig: int) -> None:
        rig = conformance_rig
        # no dead-man watchdog: only the shutdown may stop the axis
        node = rig.start_node('command_timeout:=0.0')
        self.start_far_move(rig)
        node.send_signal(sig)
        node.process.wait(30)
        self.wait_stopped(rig, self.far_move[0], f'the axis to stop on {sig!r}')
        rig.stop_node()

    @pytest.mark.ros
    def test_a_goal_running_at_shutdown_gets_its_result(
            self, conformance_rig: ConformanceRig) -> None:
        """Its client hears how the goal ended (aborted, the axis stopped) instead of
        waiting for a server that has gone."""
        rig = conformance_rig
        node = rig.start_node('command_timeout:=0.0')
        joint, position, speed = self.far_move
        with ThreadPoolExecutor(1) as pool:
            running = pool.submit(self.move_to, rig.ros, {joint: position}, [speed], 40.0)
            wait_for(lambda: rig.sim.moving(joint) or running.done(), 20.0,
                     f'{joint} moving for the goal')
            node.send_signal(signal.SIGINT)
            result, status, _ = running.result(60)
        node.process.wait(30)
        assert status == GoalStatus.STATUS_ABORTED, (status, result.message)
        assert result.message == 'stopped: the driver is shutting down', result.message
        self.wait_stopped(rig, joint, 'the axis to stop at the shutdown')
        rig.stop_node()

    @pytest.mark.ros
    @pytest.mark.parametrize('case', ['position_min count', 'publish_rate zero'])
    def test_invalid_parameters_are_refused_at_startup(self, case: str) -> None:
        count = len(self.joints) + 1
        parameter, expected = {
            'position_min count': (f'position_min:={[-1.0] * count}',
                                   f'position_min has {count} values'),
            'publish_rate zero': ('publish_rate:=0.0', 'publish_rate'),
        }[case]
        with DomainLease() as domain:
            node = ManagedProcess.ros(self.package, self.node_executable, domain,
                                      ['--ros-args', '-p', parameter])
            try:
                node.process.wait(60)
            finally:
                node.stop()
        assert node.process.returncode == 2, node.output()[-2000:]
        assert expected in node.output()
