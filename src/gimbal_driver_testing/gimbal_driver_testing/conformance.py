"""One conformance suite for the common driver contract, subclassed once per driver.

Like python-can's ``test/back2back_test.py``: the tests live here once; each driver's
``test/test_conformance.py`` subclasses :class:`DriverConformance`, names its registry
spec (``driver``: the node, and the simulator handle that runs in the test process and
observes what reached the device), joints and a few safe motions. The subclass sets
``__test__ = True``; this base is not collected.

One simulator serves a whole class. The shared node runs with the test-speed parameters
of :meth:`DriverConformance.node_parameters` (``publish_rate`` stays at its default, so
the diagnostics check is "at default parameters"); tests that must restart or kill the
node (preset persistence, lifecycle, signals) start their own node against the same
simulator, and the next test that needs the shared node starts it again. Every wait is
"until a condition holds, up to a generous timeout"; nothing asserts timings.
"""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from collections.abc import Iterator, Sequence

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_common.command_stream import GAP_TEXT, GAPS_KEY
from gimbal_driver_common.rejections import LOG_PERIOD_S
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance_rig import (
    COMMAND_PART,
    OK,
    REJECTED,
    ConformanceRig,
    GoalStatus,
    SimulatorHandle,
    command_counts,
    frequency_level_fits,
    measured_hz,
)
from gimbal_driver_testing.diagnostics_conformance import DiagnosticsConformance
from gimbal_driver_testing.effort_conformance import EffortConformance
from gimbal_driver_testing.log_conformance import LogConformance
from gimbal_driver_testing.motion_start_conformance import MotionStartConformance
from gimbal_driver_testing.restart_conformance import RestartConformance
from gimbal_driver_testing.silent_request_conformance import SilentRequestConformance
from gimbal_driver_testing.stop_conformance import StopConformance
from gimbal_driver_testing.topic_system_conformance import TopicInterfaceConformance
from gimbal_msgs.action import Home, MoveTo
from gimbal_msgs.srv import ClearPreset, GotoPreset, ListPresets, SetPreset, StartScan

__all__ = ['ConformanceRig', 'DriverConformance', 'GoalStatus', 'SimulatorHandle']

#: the shared node's dead-man timeout (node_parameters)
COMMAND_TIMEOUT_S = 0.5
#: at most this many 0.5 s bursts of refused commands until 20 are counted
REJECTED_BURSTS = 6


class DriverConformance(TopicInterfaceConformance, RestartConformance, MotionStartConformance,
                        LogConformance, DiagnosticsConformance, SilentRequestConformance,
                        StopConformance, EffortConformance):
    """The common contract of every gimbal driver node, tested through the real transport.

    Subclasses set the attributes below; the package, node and simulator come from the
    registry spec ``driver`` names.
    """

    __test__ = False  # a subclass per driver sets True

    joints: Sequence[str] = ()
    #: absolute joint positions every axis reaches quickly from anywhere (rad / m)
    small_move: dict[str, float] = {}
    #: (joint, far position, slow speed): a move that lasts several seconds
    far_move: tuple[str, float, float] = ('', 0.0, 0.0)
    #: (joint, velocity) of a jog that the device shows as motion
    jog: tuple[str, float] = ('', 0.0)
    #: position tolerance for "reached" (rad / m)
    tolerance: float = 0.02
    #: whether ~/home exists; if not, ``home_refusal`` is a text its clear failure names
    has_home: bool = True
    home_refusal: str = ''
    #: a preset index the driver stores positions under, and whether it survives a node
    #: restart (driver-side presets in presets_file, or presets kept by the device)
    preset_index: int = 4
    #: fields of a StartScan request the driver accepts (pattern included)
    scan: dict[str, object] = {}
    #: the scan status the device shows while scanning is checked through ``moving``
    scan_joint: str = 'pan'
    #: a word the connection diagnostic's ERROR message uses for a dropped link
    link_lost_text: str = 'disconnected'
    #: node parameters under which every answer the simulator gives counts, for a case
    #: that needs them all and tests no timeout: the simulator shares the test process,
    #: and on a loaded core an answer can come after a driver's default timeout
    answer_parameters: tuple[str, ...] = ()

    # ------------------------------------------------------------------ hooks
    def check_jog_running(self, rig: ConformanceRig) -> None:
        """Device-specific checks while a jog runs (e.g. the mode the device reports)."""

    def node_parameters(self) -> list[str]:
        """Test-speed parameters of the shared node (publish_rate stays at its default)."""
        return ['reconnect_period:=0.3', 'diagnostics_period:=0.25',
                f'command_timeout:={COMMAND_TIMEOUT_S}']

    # ---------------------------------------------------------------- fixtures
    @pytest.fixture(scope='class')
    @classmethod
    def conformance_rig(cls, tmp_path_factory) -> Iterator[ConformanceRig]:
        rig = ConformanceRig(cls(), tmp_path_factory.mktemp(f'{cls.driver}-conformance'))
        try:
            yield rig
        finally:
            rig.close()

    @pytest.fixture
    def rig(self, conformance_rig: ConformanceRig) -> ConformanceRig:
        """The class rig with its shared node running. A test that (re)starts the node it
        tests takes ``conformance_rig`` instead: the shared node restarted for it would be
        stopped again at once, a node start (about 1 s of CPU) for nothing."""
        conformance_rig.shared_node()
        return conformance_rig

    # ------------------------------------------------------------------ tests
    @pytest.mark.ros
    def test_joint_states_names_units_and_rate(self, rig: ConformanceRig) -> None:
        ros = rig.ros
        msg = ros.wait_for_message('joint_states', JointState)
        assert list(msg.name) == list(self.joints)
        assert len(msg.position) == len(msg.velocity) == len(self.joints)
        assert msg.header.stamp.sec > 0
        # SI units: every position lies within the joint limits the node declares (rad/m).
        low = ros.get_parameter(self.node_name, 'position_min')
        high = ros.get_parameter(self.node_name, 'position_max')
        for name, position, lo, hi in zip(msg.name, msg.position, low, high, strict=True):
            assert math.isfinite(position) and lo - 1e-6 <= position <= hi + 1e-6, name
        # rate: the node's own frequency check measures what it publishes and gives the
        # level its documented window does (OK on a machine that keeps up, WARN on one
        # that really starves the node: a figure of the machine, not a verdict). The wait
        # is for a window that saw messages: the first window after activation is one
        # diagnostics period (0.25 s here), and a node or simulator the machine starved
        # for that long really published nothing in it ("no events", docs/testing.md).
        status = ros.wait_for_diagnostic(
            self.node_name, 'joint_states frequency',
            lambda s: s.message != 'measuring' and measured_hz(s) > 0, timeout=40)
        assert frequency_level_fits(status), (status.level, status.message, status.values)
        values = {kv.key: kv.value for kv in status.values}
        rate = ros.get_parameter(self.node_name, 'publish_rate')
        assert float(values['expected_hz']) <= rate + 1e-6

    @pytest.mark.ros
    def test_every_diagnostic_is_ok_against_a_healthy_simulator(
            self, rig: ConformanceRig) -> None:
        def all_ok(array: DiagnosticArray) -> bool:
            """Every part OK; the frequency measured, at the level its own rate gives (WARN
            is true of a node the machine starves; frequency_level_fits)."""
            statuses = self.node_statuses(array)
            frequency = [s for s in statuses if s.name.endswith('joint_states frequency')]
            return (bool(frequency) and all(s.message != 'measuring' and
                                            frequency_level_fits(s) for s in frequency)
                    and all(s.level[0] == OK for s in statuses if s not in frequency))

        try:
            rig.ros.wait_for_message('/diagnostics', DiagnosticArray, all_ok, timeout=40)
        except TimeoutError:
            last = rig.ros.wait_for_message('/diagnostics', DiagnosticArray)
            bad = [(s.name, s.level[0], s.message) for s in self.node_statuses(last)
                   if s.level[0] != OK]
            raise AssertionError(f'diagnostics not all OK: {bad}') from None

    @pytest.mark.ros
    def test_joint_command_absolute_move(self, rig: ConformanceRig) -> None:
        rig.ros.publish('joint_command', JointState(name=list(self.small_move),
                                                    position=list(self.small_move.values())))
        self.wait_positions(rig.ros, self.small_move)

    @pytest.mark.ros
    def test_jog_is_stopped_by_the_dead_man_watchdog(self, rig: ConformanceRig) -> None:
        joint, velocity = self.jog
        index = list(self.joints).index(joint)
        rig.ros.publish('joint_command', JointState(name=[joint], velocity=[velocity]))
        wait_for(lambda: rig.sim.moving(joint), 20.0, f'the {joint} jog to start')
        self.check_jog_running(rig)
        # no further joint_command: the watchdog (command_timeout) stops the axis
        self.wait_stopped(rig, joint, 'the watchdog to stop the jog')
        rig.ros.wait_for_message('joint_states', JointState,
                                 lambda m: abs(m.velocity[index]) < 1e-3, timeout=20)
        rig.node.wait_for_output('expired')

    @pytest.mark.ros
    def test_a_jog_the_node_took_late_is_told_from_a_client_that_paused(
            self, rig: ConformanceRig) -> None:
        """The node stands still (SIGSTOP) while the test keeps publishing its jog every
        20 ms: it took no command for longer than ``command_timeout`` while the publisher
        did not pause, and says so (command_stream) in its log and diagnostics."""
        joint, velocity = self.jog
        node, ros = rig.node, rig.ros
        command = JointState(name=[joint], velocity=[velocity])
        ros.publish('joint_command', command)
        wait_for(lambda: rig.sim.moving(joint), 20.0, f'the {joint} jog to start')
        publishing, paused = threading.Event(), threading.Event()

        def stream() -> None:  # the client: a steady 50 Hz, through the pause
            while not publishing.wait(0.02):
                ros.publish('joint_command', command)
        streamer = threading.Thread(target=stream, name='jog-stream')
        streamer.start()
        try:
            os.killpg(node.process.pid, signal.SIGSTOP)
            paused.wait(2 * COMMAND_TIMEOUT_S)  # the stimulus: twice the dead-man window
            os.killpg(node.process.pid, signal.SIGCONT)
            node.wait_for_output(GAP_TEXT, 20.0)
        finally:
            os.killpg(node.process.pid, signal.SIGCONT)
            publishing.set()
            streamer.join()
        rig.ros.wait_for_diagnostic(self.node_name, COMMAND_PART,
                                    lambda s: command_counts(s)[GAPS_KEY] >= 1, timeout=20.0)
        self.wait_stopped(rig, joint, 'the watchdog to stop the jog once the stream ended')
        rig.stop_node()  # the next test gets a node that never stood still

    @pytest.mark.ros
    def test_stop_service_halts_a_move(self, rig: ConformanceRig) -> None:
        self.start_far_move(rig)
        reply = rig.ros.call(Trigger, self.srv('stop'), Trigger.Request())
        assert reply.success, reply.message
        self.wait_stopped(rig, self.far_move[0], 'the axis to stop')
        self.assert_short_of_far_target(rig)

    @pytest.mark.ros
    @pytest.mark.parametrize(('case', 'message', 'reason'), [
        ('unknown joint', 'unknown joint', 'unknown joint'),
        ('inf position', 'not a finite number', '{first}: position not finite'),
        ('inf velocity', 'not a finite number', '{first}: velocity not finite'),
        ('velocity above velocity_max', 'exceeds velocity_max',
         '{first}: velocity above velocity_max'),
        ('position outside the limits', 'outside', '{first}: position outside the limits'),
        ('names and positions differ in length', 'joint names but',
         'position values do not match the names'),
        ('names and velocities differ in length', 'joint names but',
         'velocity values do not match the names'),
    ])
    def test_bad_joint_command_is_rejected_and_nothing_sent(
            self, rig: ConformanceRig, case: str, message: str, reason: str) -> None:
        first, second = list(self.joints)[:2]
        msg = {
            'unknown joint': JointState(name=['elbow'], position=[0.1]),
            'inf position': JointState(name=[first, second], position=[math.inf, math.nan]),
            'inf velocity': JointState(name=[first], velocity=[-math.inf]),
            'position outside the limits': JointState(name=[first], position=[1e6]),
            'velocity above velocity_max': JointState(name=[first], position=[math.nan],
                                                      velocity=[1e3]),
            'names and positions differ in length': JointState(
                name=[first, second], position=[0.1]),
            'names and velocities differ in length': JointState(
                name=[first], velocity=[0.1, 0.1]),
        }[case]
        key = f'rejected: {reason.format(first=first)}'
        counted = self.rejections(rig.ros).get(key, 0)
        before = rig.sim.motion_received()
        rig.ros.publish('joint_command', msg)
        self.rejections(rig.ros, lambda counts: counts.get(key, 0) > counted)
        # the reason is logged (once per reason every few seconds, so maybe by an earlier one)
        lines = [line for line in rig.node.output().splitlines() if REJECTED in line]
        assert any(message in line.split(REJECTED)[-1] for line in lines), lines[-5:]
        assert rig.sim.motion_received() == before

    @pytest.mark.ros
    def test_a_stream_of_rejected_commands_is_counted_and_logged_once(
            self, rig: ConformanceRig) -> None:
        """A controller streaming refused commands (100 Hz) must not flood the log: each
        reason at most once every few seconds, every message counted in diagnostics.

        joint_command is keep-last 1, so a node starved of CPU keeps only the newest of
        what arrived meanwhile: the stream goes on, in bursts of 0.5 s, until 20 are
        counted, and the log may hold one line per LOG_PERIOD_S it took."""
        first = self.joints[0]
        key = f'rejected: {first}: position outside the limits'
        counted = self.rejections(rig.ros).get(key, 0)
        logged, start = len(rig.node.output()), time.monotonic()
        for _burst in range(REJECTED_BURSTS):
            for i in range(50):  # 0.5 s of a 100 Hz stream, every message out of the limits
                rig.ros.publish('joint_command', JointState(name=[first], position=[1e6 + i]))
                time.sleep(0.01)
            try:
                counts = self.rejections(
                    rig.ros, lambda counts: counts.get(key, 0) >= counted + 20, timeout=3.0)
                break
            except TimeoutError:
                continue
        else:
            pytest.fail(f'fewer than 20 of {50 * REJECTED_BURSTS} refused commands counted: '
                        f'{self.rejections(rig.ros)}')
        assert counts['rejected'] >= counts[key]
        lines = [line for line in rig.node.output()[logged:].splitlines()
                 if f"joint {first!r}: position" in line]
        periods = 1 + int((time.monotonic() - start) / LOG_PERIOD_S)
        assert len(lines) <= periods, lines
        level = rig.ros.wait_for_diagnostic(self.node_name, COMMAND_PART).level[0]
        assert level == OK  # the client's fault, not the device's

    @pytest.mark.ros
    def test_nan_joints_are_left_alone_and_the_others_carried_out(
            self, rig: ConformanceRig) -> None:
        """NaN = no command for that joint (ros2_control's topic interface sends it for
        joints whose controller has not started)."""
        first, second = list(self.small_move)[:2]
        assert self.move_to(rig.ros, self.small_move)[0].success
        away = self.small_move[second] + (0.1 if self.small_move[second] <= 0 else -0.1)
        counted = self.rejections(rig.ros)
        rig.ros.publish('joint_command', JointState(name=[first, second],
                                                    position=[math.nan, away]))
        self.wait_positions(rig.ros, {first: self.small_move[first], second: away})
        assert not rig.sim.moving(first)
        after = self.rejections(rig.ros)
        assert (after['rejected'], after['refused']) == (counted['rejected'],
                                                         counted['refused'])

    @pytest.mark.ros
    def test_bad_move_to_goals_are_refused_and_nothing_sent(self, rig: ConformanceRig) -> None:
        first = self.joints[0]
        before = rig.sim.motion_received()
        # NaN stays an error in a goal: it names the joints it promises to reach
        for targets, reason in (({'elbow': 0.0}, 'unknown joint'),
                                ({first: math.nan}, 'NaN is not a target'),
                                ({first: math.inf}, 'not a finite number'),
                                ({first: 1e6}, 'outside')):
            result, status, _ = self.move_to(rig.ros, targets)
            assert not result.success and reason in result.message, (targets, result.message)
            assert status == GoalStatus.STATUS_ABORTED
        result, _, _ = self.move_to(rig.ros, {first: self.small_move.get(first, 0.0)}, [1e3])
        assert not result.success and 'velocity_max' in result.message, result.message
        goal = MoveTo.Goal(joint_names=[first, self.joints[1]], positions=[0.0])
        result, _, _ = rig.ros.run_action(MoveTo, self.srv('move_to'), goal)
        assert not result.success and 'positions' in result.message, result.message
        assert rig.sim.motion_received() == before

    @pytest.mark.ros
    def test_move_to_reaches_its_target(self, rig: ConformanceRig) -> None:
        away = {j: p + (0.1 if p <= 0 else -0.1) for j, p in self.small_move.items()}
        assert self.move_to(rig.ros, away)[0].success
        before = rig.sim.motion_received()
        result, status, feedback = self.move_to(rig.ros, self.small_move)
        # the device-side observer sees a move (so its "nothing sent" checks mean something)
        assert rig.sim.motion_received() != before
        assert result.success, result.message
        assert status == GoalStatus.STATUS_SUCCEEDED
        assert result.positions == pytest.approx(list(self.small_move.values()),
                                                 abs=self.tolerance)
        assert feedback, 'MoveTo publishes feedback while moving'
        self.wait_positions(rig.ros, self.small_move)

    @pytest.mark.ros
    def test_move_to_cancel_stops_the_axis(self, rig: ConformanceRig) -> None:
        joint, position, speed = self.far_move
        result, status, _ = self.move_to(rig.ros, {joint: position}, [speed],
                                         cancel_after=1.0)
        assert status == GoalStatus.STATUS_CANCELED and not result.success, result.message
        self.wait_stopped(rig, joint, 'the cancelled move to stop')
        self.assert_short_of_far_target(rig)

    @pytest.mark.ros
    def test_move_to_times_out_and_stops(self, rig: ConformanceRig) -> None:
        joint, position, speed = self.far_move
        default = rig.ros.get_parameter(self.node_name, 'move_timeout')
        assert rig.ros.set_parameter(self.node_name, 'move_timeout', 0.5).successful
        try:
            result, status, _ = self.move_to(rig.ros, {joint: position}, [speed])
        finally:
            assert rig.ros.set_parameter(self.node_name, 'move_timeout', default).successful
        assert status == GoalStatus.STATUS_ABORTED and not result.success
        assert 'move_timeout' in result.message, result.message
        self.wait_stopped(rig, joint, 'the timed-out move to stop')
        self.assert_short_of_far_target(rig)

    @pytest.mark.ros
    def test_home_or_its_clear_failure(self, rig: ConformanceRig) -> None:
        result, status, feedback = rig.ros.run_action(Home, self.srv('home'), Home.Goal(),
                                                      timeout=90)
        if self.has_home:
            assert result.success, result.message
            assert status == GoalStatus.STATUS_SUCCEEDED and feedback and feedback[0].state
        else:
            assert not result.success and self.home_refusal in result.message, result.message
        bad, _, _ = rig.ros.run_action(Home, self.srv('home'), Home.Goal(joint_names=['elbow']))
        assert not bad.success and 'unknown joint' in bad.message

    @pytest.mark.ros
    def test_presets_set_list_goto_clear(self, rig: ConformanceRig) -> None:
        ros, index = rig.ros, self.preset_index
        reply = ros.call(SetPreset, self.srv('set_preset'), SetPreset.Request(
            index=index, name='conformance', joint_names=list(self.small_move),
            positions=list(self.small_move.values())))
        assert reply.success, reply.message
        first = self.joints[0]
        before = rig.sim.motion_received()
        bad = ros.call(SetPreset, self.srv('set_preset'), SetPreset.Request(
            index=index + 1, name='bad', joint_names=[first], positions=[1e6]))
        assert not bad.success and 'outside' in bad.message, bad.message
        assert rig.sim.motion_received() == before
        listed = ros.call(ListPresets, self.srv('list_presets'), ListPresets.Request())
        assert listed.success
        preset = {p.index: p for p in listed.presets}[index]
        stored = dict(zip(preset.joint_names, preset.positions, strict=True))
        for joint, position in self.small_move.items():
            assert stored[joint] == pytest.approx(position, abs=1e-3)
        # away, then back to the preset
        away = {j: p + (0.1 if p <= 0 else -0.1) for j, p in self.small_move.items()}
        assert self.move_to(ros, away)[0].success
        go = ros.call(GotoPreset, self.srv('goto_preset'), GotoPreset.Request(index=index))
        assert go.success, go.message
        self.wait_positions(ros, self.small_move)
        missing = ros.call(GotoPreset, self.srv('goto_preset'), GotoPreset.Request(index=99))
        assert not missing.success and '99' in missing.message, missing.message
        cleared = ros.call(ClearPreset, self.srv('clear_preset'), ClearPreset.Request(index=index))
        assert cleared.success, cleared.message
        listed = ros.call(ListPresets, self.srv('list_presets'), ListPresets.Request())
        assert index not in [p.index for p in listed.presets]
        cleared = ros.call(ClearPreset, self.srv('clear_preset'), ClearPreset.Request(all=True))
        assert cleared.success, cleared.message

    @pytest.mark.ros
    def test_scan_start_stop_and_unknown_pattern(self, rig: ConformanceRig) -> None:
        ros = rig.ros
        before = rig.sim.motion_received()
        unknown = ros.call(StartScan, self.srv('start_scan'), StartScan.Request(
            **{**self.scan, 'pattern': 'lissajous'}))
        assert not unknown.success and 'lissajous' in unknown.message, unknown.message
        assert rig.sim.motion_received() == before
        reply = ros.call(StartScan, self.srv('start_scan'), StartScan.Request(**self.scan))
        assert reply.success, reply.message
        wait_for(lambda: rig.sim.moving(self.scan_joint), 20.0, 'the scan to move the axis')
        stop = ros.call(Trigger, self.srv('stop_scan'), Trigger.Request())
        assert stop.success, stop.message
        self.wait_stopped(rig, self.scan_joint, 'the scan to stop')
        # the driver left scan mode: a move works
        result, _, _ = self.move_to(ros, self.small_move)
        assert result.success, result.message

    # ------------------------------------------------- tests that restart the node
