"""kOS parameters changed while the node runs (`ros2 param set`), node against kessler_kos_sim.

joint_scales are the interesting one: they change the conversion of every reading and
command, so they are taken only while the axes are idle.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_common.testing import free_tcp_port
from gimbal_driver_common.testing.ros import RosTestClient, driver_rig, joint_positions
from gimbal_msgs.action import MoveTo
from gimbal_msgs.msg import AxisState, AxisTrajectory, BezierSegment, GimbalStatus
from gimbal_msgs.srv import LoadTrajectory

pytestmark = pytest.mark.ros

PKG = 'kessler_kos_driver'
NODE = 'kessler_kos_driver'
TWO_PI = 2.0 * math.pi


@pytest.fixture(scope='module')
def rig():
    port = free_tcp_port()
    with driver_rig(PKG, 'kessler_kos_sim', [
            '--port', str(port), '--control-port', str(free_tcp_port()),
            '--discovery-port', '0', '--password', 'pw-runtime', '--precalibrated',
            '--time-scale', '2'], '{"ready": "kessler_kos_sim"', 'kessler_kos_driver_node', [
            'host:=127.0.0.1', f'port:={port}', 'password:=pw-runtime',
            'reconnect_period:=0.2', 'command_timeout:=0.0']) as rig:
        yield rig.ros, rig.node


def pan_near(ros: RosTestClient, value: float, timeout: float = 20.0) -> JointState:
    return ros.wait_for_message(
        'joint_states', JointState,
        lambda m: abs(joint_positions(m).get('pan', math.inf) - value) < 1e-3
        and abs(m.velocity[m.name.index('pan')]) < 1e-4, timeout=timeout)


def test_joint_scales_apply_while_idle(rig) -> None:
    ros, _ = rig
    goal = MoveTo.Goal(joint_names=['pan'], positions=[20.0])
    result, _, _ = ros.run_action(MoveTo, f'/{NODE}/move_to', goal, timeout=30)
    assert result.success, result.message
    pan_near(ros, 20.0)
    # Half the SI units per rotation: the same motor position now reads 10 rad.
    result = ros.set_parameter(NODE, 'joint_scales', [TWO_PI, math.pi, TWO_PI])
    assert result.successful, result.reason
    pan_near(ros, 10.0)
    status = ros.wait_for_message(f'/{NODE}/status', GimbalStatus, timeout=15)
    assert status.axes[1].target_position == pytest.approx(10.0)  # the target converts too
    # ... and commands convert with the new scale too.
    goal = MoveTo.Goal(joint_names=['pan'], positions=[15.0])
    result, _, _ = ros.run_action(MoveTo, f'/{NODE}/move_to', goal, timeout=30)
    assert result.success, result.message
    assert ros.set_parameter(NODE, 'joint_scales', [TWO_PI, TWO_PI, TWO_PI]).successful
    pan_near(ros, 30.0)


def scale_change_refusal(ros: RosTestClient) -> str:
    """Try a joint_scales change that the node must refuse while the axes move; the reason."""
    refused = ros.set_parameter(NODE, 'joint_scales', [TWO_PI, math.pi, TWO_PI])
    assert not refused.successful
    assert 'axes must be idle' in refused.reason
    return refused.reason


def test_joint_scales_refused_while_jogging_and_when_invalid(rig) -> None:
    ros, _ = rig
    ros.publish('joint_command', JointState(name=['pan'], velocity=[2.0]))
    try:
        ros.wait_for_message('joint_states', JointState,
                             lambda m: abs(m.velocity[m.name.index('pan')]) > 1.0, timeout=10)
        assert 'pan' in scale_change_refusal(ros)
    finally:
        assert ros.call(Trigger, f'/{NODE}/stop', Trigger.Request()).success
    assert ros.get_parameter(NODE, 'joint_scales') == [TWO_PI, TWO_PI, TWO_PI]
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
        assert 'a move is playing' in scale_change_refusal(ros)
    finally:
        assert ros.call(Trigger, f'/{NODE}/stop_playback', Trigger.Request()).success
    assert ros.get_parameter(NODE, 'joint_scales') == [TWO_PI, TWO_PI, TWO_PI]


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


def test_poll_period_sets_the_joint_states_rate(rig) -> None:
    ros, _ = rig
    result = ros.set_parameter(NODE, 'poll_period', 0.25)
    assert result.successful, result.reason
    try:
        ros.mean_stamp_gap('joint_states', JointState, 1)  # let a sample of the old rate pass
        assert ros.mean_stamp_gap('joint_states', JointState, 4) >= 0.2  # 4 Hz polls
    finally:
        result = ros.set_parameter(NODE, 'poll_period', 0.02)
        assert result.successful, result.reason
    ros.mean_stamp_gap('joint_states', JointState, 1)
    assert ros.mean_stamp_gap('joint_states', JointState, 20) < 0.15  # 50 Hz polls
    refused = ros.set_parameter(NODE, 'poll_period', -1.0)
    assert not refused.successful and 'poll_period' in refused.reason
