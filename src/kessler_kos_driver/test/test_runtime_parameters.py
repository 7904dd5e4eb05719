"""kOS parameters changed while the node runs (`ros2 param set`), node against kessler_kos_sim.

The unit parameters (calibrated_spans, joint_offsets, joint_scales) are the interesting ones:
they change the conversion of every reading and command, so they are taken only while the
axes are idle. The rig is the simulator's example rig in SI for pan and tilt, and a slider
without a span: it reports motor radians (joint_scales 2*pi) and the node says so.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_testing import free_tcp_port, wait_for
from gimbal_driver_testing.ros import (
    RosTestClient,
    driver_rig,
    find_diagnostic,
    joint_positions,
)
from gimbal_msgs.action import MoveTo
from gimbal_msgs.msg import AxisState, AxisTrajectory, BezierSegment, GimbalStatus
from gimbal_msgs.srv import LoadTrajectory

pytestmark = pytest.mark.ros

PKG = 'kessler_kos_driver'
NODE = 'kessler_kos_driver'
TWO_PI = 2.0 * math.pi
SPANS = [0.0, TWO_PI, math.pi]                # slider: no span
OFFSETS = [0.0, -math.pi, -math.pi / 2]
SCALES = [TWO_PI, TWO_PI, TWO_PI]


@pytest.fixture(scope='module')
def rig():
    port = free_tcp_port()
    with driver_rig(PKG, 'kessler_kos_sim', [
            '--port', str(port), '--control-port', str(free_tcp_port()),
            '--discovery-port', '0', '--password', 'pw-runtime', '--precalibrated',
            '--time-scale', '2'], '{"ready": "kessler_kos_sim"', 'kessler_kos_driver_node', [
            'host:=127.0.0.1', f'port:={port}', 'password:=pw-runtime',
            'reconnect_period:=0.2', 'command_timeout:=0.0', 'diagnostics_period:=0.25',
            f'calibrated_spans:={SPANS}', f'joint_offsets:={OFFSETS}',
            'position_max:=[200.0, 3.141592653589793, 1.5707963267948966]',
            'velocity_max:=[100.0, 1.5, 1.0]']) as rig:
        yield rig.ros, rig.node


def joint_near(ros: RosTestClient, joint: str, value: float,
               timeout: float = 20.0) -> JointState:
    """A joint_states message with ``joint`` at rest at ``value``."""
    return ros.wait_for_message(
        'joint_states', JointState,
        lambda m: abs(joint_positions(m).get(joint, math.inf) - value) < 1e-3
        and abs(m.velocity[m.name.index(joint)]) < 1e-4, timeout=timeout)


def move(ros: RosTestClient, **targets: float) -> None:
    goal = MoveTo.Goal(joint_names=list(targets), positions=list(targets.values()))
    result, _, _ = ros.run_action(MoveTo, f'/{NODE}/move_to', goal, timeout=30)
    assert result.success, result.message


def axis_units(ros: RosTestClient, joint: str, units: str) -> dict[str, str]:
    """The joint's diagnostics values once its ``units`` key reads ``units``."""
    def matches(array: DiagnosticArray) -> bool:
        status = find_diagnostic(array, NODE, joint)
        return status is not None and any(kv.key == 'units' and kv.value == units
                                           for kv in status.values)

    array = ros.wait_for_message('/diagnostics', DiagnosticArray, matches, timeout=15)
    status = find_diagnostic(array, NODE, joint)
    assert status.level[0] == 0     # OK: motor radians are a fact to state, not a fault
    return {kv.key: kv.value for kv in status.values}


@contextmanager
def restored(ros: RosTestClient) -> Iterator[None]:
    """Put the unit parameters back afterwards (tests share the node, in any order)."""
    try:
        yield
    finally:
        assert ros.call(Trigger, f'/{NODE}/stop', Trigger.Request()).success
        ros.wait_for_message('joint_states', JointState,
                             lambda m: all(abs(v) < 1e-4 for v in m.velocity), timeout=20)
        for name, values in (('joint_scales', SCALES), ('calibrated_spans', SPANS),
                             ('joint_offsets', OFFSETS)):
            result = ros.set_parameter(NODE, name, values)
            assert result.successful, result.reason


def test_an_axis_without_a_span_reports_motor_radians_and_says_so(rig) -> None:
    ros, node = rig
    # once in the log at configure, naming the axis and the parameters to set
    node.wait_for_output("joint 'slider' reports motor-shaft radians")
    output = node.output()
    assert output.count("reports motor-shaft radians") == 1, output
    line = next(x for x in output.splitlines() if 'motor-shaft radians' in x)
    assert 'calibrated_spans' in line and 'joint_scales' in line
    assert ("joint units: slider motor radians, pan SI (calibrated_spans), tilt SI "
            "(calibrated_spans)") in output
    values = axis_units(ros, 'slider', 'motor radians')
    assert float(values['si_per_rotation']) == pytest.approx(TWO_PI, abs=1e-5)
    assert axis_units(ros, 'pan', 'SI (calibrated_spans)')['calibrated_span'] == '6.28319'


def test_joint_scales_apply_while_idle(rig) -> None:
    ros, _ = rig
    with restored(ros):
        move(ros, slider=10.0)              # motor radians: 1.59 rotations
        joint_near(ros, 'slider', 10.0)
        # Half the SI units per rotation: the same motor position now reads 5.
        result = ros.set_parameter(NODE, 'joint_scales', [math.pi, TWO_PI, TWO_PI])
        assert result.successful, result.reason
        joint_near(ros, 'slider', 5.0)
        status = ros.wait_for_message(f'/{NODE}/status', GimbalStatus, timeout=15)
        assert status.axes[0].target_position == pytest.approx(5.0)  # the target converts
        axis_units(ros, 'slider', 'SI (joint_scales)')
        # ... and commands convert with the new scale too.
        move(ros, slider=7.5)
        assert ros.set_parameter(NODE, 'joint_scales', SCALES).successful
        joint_near(ros, 'slider', 15.0)
        axis_units(ros, 'slider', 'motor radians')


def test_calibrated_spans_and_offsets_apply_while_idle(rig) -> None:
    ros, _ = rig
    with restored(ros):
        move(ros, pan=0.0)                  # 50 rotations: the middle of 0..100
        # the begin mark a quarter turn further left: the same motor position reads +pi/2
        result = ros.set_parameter(NODE, 'joint_offsets', [0.0, -math.pi / 2, -math.pi / 2])
        assert result.successful, result.reason
        joint_near(ros, 'pan', math.pi / 2)
        # a half turn from begin to end mark: 50 rotations are now a quarter turn on
        result = ros.set_parameter(NODE, 'calibrated_spans', [0.0, math.pi, math.pi])
        assert result.successful, result.reason
        joint_near(ros, 'pan', 0.0)
        move(ros, pan=-math.pi / 4)        # a quarter of the half turn: 25 rotations
        # the slider gets a span: 1.5 m over its 0..200 calibrated rotations, in SI at once
        move(ros, slider=TWO_PI * 20)       # 20 rotations
        result = ros.set_parameter(NODE, 'calibrated_spans', [1.5, math.pi, math.pi])
        assert result.successful, result.reason
        joint_near(ros, 'slider', 0.15)
        axis_units(ros, 'slider', 'SI (calibrated_spans)')
        refused = ros.set_parameter(NODE, 'calibrated_spans', [1.5, math.inf, math.pi])
        assert not refused.successful and 'calibrated_spans: need 3 finite' in refused.reason
        refused = ros.set_parameter(NODE, 'joint_offsets', [0.0])
        assert not refused.successful and 'joint_offsets: need 3' in refused.reason
    joint_near(ros, 'pan', -math.pi / 2)   # restored: 25 rotations of -pi..pi over 0..100


def units_change_refusal(ros: RosTestClient) -> str:
    """Try unit changes that the node must refuse while the axes move; the reason."""
    for name, values in (('joint_scales', [math.pi, TWO_PI, TWO_PI]),
                         ('calibrated_spans', [1.5, TWO_PI, math.pi]),
                         ('joint_offsets', [0.0, 0.0, 0.0])):
        refused = ros.set_parameter(NODE, name, values)
        assert not refused.successful, name
        assert 'axes must be idle' in refused.reason
    return refused.reason


def test_joint_scales_refused_while_jogging_and_when_invalid(rig) -> None:
    ros, _ = rig
    ros.publish('joint_command', JointState(name=['pan'], velocity=[0.2]))
    try:
        ros.wait_for_message('joint_states', JointState,
                             lambda m: abs(m.velocity[m.name.index('pan')]) > 0.1, timeout=10)
        assert 'pan' in units_change_refusal(ros)
    finally:
        assert ros.call(Trigger, f'/{NODE}/stop', Trigger.Request()).success
    assert ros.get_parameter(NODE, 'joint_scales') == SCALES
    assert ros.get_parameter(NODE, 'calibrated_spans') == SPANS
    refused = ros.set_parameter(NODE, 'joint_scales', [TWO_PI, 0.0, TWO_PI])
    assert not refused.successful and 'finite non-zero' in refused.reason
    refused = ros.set_parameter(NODE, 'joint_scales', [TWO_PI])
    assert not refused.successful and 'need 3' in refused.reason


def test_joint_scales_refused_while_a_move_plays(rig) -> None:
    ros, _ = rig
    segment = BezierSegment(p0_time=0.0, p0_position=0.0, p1_time=1 / 3, p1_position=0.0,
                            p2_time=2 / 3, p2_position=0.2, p3_time=1.0, p3_position=0.2)
    load = LoadTrajectory.Request(
        playback_mode=LoadTrajectory.Request.MODE_LIVE_MOTION, duration=4.0, loop_count=255,
        rapid_reverse=True, axes=[AxisTrajectory(joint_name='pan', segments=[segment])])
    reply = ros.call(LoadTrajectory, f'/{NODE}/load_trajectory', load)
    assert reply.success, reply.message
    assert ros.call(Trigger, f'/{NODE}/start_playback', Trigger.Request()).success
    try:
        ros.wait_for_message(f'/{NODE}/status', GimbalStatus,
                             lambda s: s.axes[1].state == AxisState.STATE_PLAYBACK, timeout=15)
        assert 'a move is playing' in units_change_refusal(ros)
    finally:
        assert ros.call(Trigger, f'/{NODE}/stop_playback', Trigger.Request()).success
    assert ros.get_parameter(NODE, 'joint_scales') == SCALES
    assert ros.get_parameter(NODE, 'joint_offsets') == OFFSETS


def test_other_kos_parameters(rig) -> None:
    ros, _ = rig
    assert ros.set_parameter(NODE, 'picture_exposure', 0.02).successful
    reply = ros.call(Trigger, f'/{NODE}/take_picture', Trigger.Request())
    assert reply.success and 'exposure 0.02 s' in reply.message, reply.message
    refused = ros.set_parameter(NODE, 'acceleration_scale', 2.0)  # fraction 0.01..1
    assert not refused.successful and 'acceleration_scale' in refused.reason
    refused = ros.set_parameter(NODE, 'password', 'guess')
    assert not refused.successful and 'read-only' in refused.reason
    assert 'guess' not in refused.reason
    refused = ros.set_parameter(NODE, 'motor_addresses', [3, 2, 1])
    assert not refused.successful and 'needs reconfigure' in refused.reason


def mean_gap_after(ros: RosTestClient, since: float, count: int) -> float:
    """Mean gap between the stamps of ``count`` + 1 joint_states stamped after ``since``
    (the system clock the node stamps on), the first such one skipped (a poll begun at the
    old rate). Not "the next ones received": a loaded machine delivers a backlog of the
    old rate after the change."""
    received = ros.subscribe('joint_states', JointState)

    def stamps() -> list[float]:
        found = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in list(received)]
        return [stamp for stamp in found if stamp > since][1:count + 2]

    wait_for(lambda: len(stamps()) == count + 1, 60.0, f'{count + 2} joint_states after')
    taken = stamps()
    return (taken[-1] - taken[0]) / count


def test_poll_period_sets_the_joint_states_rate(rig) -> None:
    ros, _ = rig
    ros.subscribe('joint_states', JointState)
    result = ros.set_parameter(NODE, 'poll_period', 0.25)
    changed = time.time()
    assert result.successful, result.reason
    try:
        assert mean_gap_after(ros, changed, 4) >= 0.2  # 4 Hz polls
    finally:
        result = ros.set_parameter(NODE, 'poll_period', 0.02)
        changed = time.time()
        assert result.successful, result.reason
    assert mean_gap_after(ros, changed, 20) < 0.15  # 50 Hz polls
    refused = ros.set_parameter(NODE, 'poll_period', -1.0)
    assert not refused.successful and 'poll_period' in refused.reason
