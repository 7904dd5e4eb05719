"""Common parameters changed while the node runs (`ros2 param set`), on the virtual gimbal.

The node runs as a process against the simulator; the test sets parameters
through the node's /<node>/set_parameters service, as `ros2 param set` does,
and watches the effect on joint_states, ~/status and the actions.
"""

from __future__ import annotations

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from gimbal_driver_testing import free_tcp_port
from gimbal_driver_testing.ros import RosTestClient, driver_rig, joint_positions
from gimbal_msgs.action import MoveTo
from gimbal_msgs.msg import GimbalStatus

pytestmark = pytest.mark.ros

PKG = 'virtual_gimbal_driver'
NODE = 'virtual_gimbal_driver'


def tilt(ros: RosTestClient, predicate) -> JointState:
    """A fresh joint_states whose tilt (position, velocity) satisfies ``predicate``."""
    return ros.wait_for_message(
        'joint_states', JointState,
        lambda m: predicate(joint_positions(m)['tilt'], m.velocity[m.name.index('tilt')]),
        timeout=20)


def move(ros: RosTestClient, names, values):
    goal = MoveTo.Goal(joint_names=list(names), positions=list(values))
    return ros.run_action(MoveTo, f'/{NODE}/move_to', goal, timeout=30)


@pytest.fixture(scope='module')
def rig():
    port = free_tcp_port()
    with driver_rig(PKG, 'virtual_gimbal_sim', ['--port', str(port)],
                    '{"ready": "virtual_gimbal_sim"',
                    'virtual_gimbal_driver_node', [f'port:={port}', 'reconnect_period:=0.2',
                                            'command_timeout:=0.4']) as rig:
        yield rig.ros, rig.node


def test_publish_rate_changes_the_joint_states_rate(rig) -> None:
    ros, _ = rig
    result = ros.set_parameter(NODE, 'publish_rate', 2.0)
    assert result.successful, result.reason
    assert ros.get_parameter(NODE, 'publish_rate') == 2.0
    ros.mean_stamp_gap('joint_states', JointState, 1)  # let a sample of the old rate pass
    assert ros.mean_stamp_gap('joint_states', JointState, 4) >= 0.4  # 2 Hz: 0.5 s apart
    result = ros.set_parameter(NODE, 'publish_rate', 50.0)
    assert result.successful, result.reason
    ros.mean_stamp_gap('joint_states', JointState, 1)
    assert ros.mean_stamp_gap('joint_states', JointState, 20) < 0.2  # 50 Hz: 0.02 s apart


def test_invalid_values_are_refused_with_the_start_up_checks(rig) -> None:
    ros, _ = rig
    refused = ros.set_parameter(NODE, 'publish_rate', 5000.0)  # descriptor range 0.1..1000
    assert not refused.successful and 'publish_rate' in refused.reason
    refused = ros.set_parameter(NODE, 'position_max', [-4.0, 1.0])  # below position_min
    assert not refused.successful and 'joint limits' in refused.reason, refused.reason
    refused = ros.set_parameter(NODE, 'velocity_max', [1.0])  # one value for two joints
    assert not refused.successful and 'velocity_max has 1 values' in refused.reason
    refused = ros.set_parameter(NODE, 'publish_rate', 'fast')  # wrong type
    assert not refused.successful
    assert ros.get_parameter(NODE, 'publish_rate') == 50.0
    assert ros.get_parameter(NODE, 'velocity_max') == [1.5, 1.5]


def test_read_only_and_reconfigure_parameters_are_refused_with_the_reason(rig) -> None:
    ros, _ = rig
    refused = ros.set_parameter(NODE, 'joint_names', ['a', 'b'])
    assert not refused.successful and 'read-only' in refused.reason
    refused = ros.set_parameter(NODE, 'port', 1234)
    assert not refused.successful and 'needs reconfigure' in refused.reason
    assert "'port'" in refused.reason
    refused = ros.set_parameter(NODE, 'presets_file', '/tmp/elsewhere.yaml')
    assert not refused.successful and 'needs reconfigure' in refused.reason


def test_new_position_limit_rejects_a_move_that_was_valid(rig) -> None:
    ros, _ = rig
    result, _, _ = move(ros, ['pan'], [0.5])
    assert result.success, result.message
    result = ros.set_parameter(NODE, 'position_max', [0.3, 1.0])
    assert result.successful, result.reason
    try:
        result, _, _ = move(ros, ['pan'], [0.2])  # within the new limit: moves
        assert result.success, result.message
        result, _, _ = move(ros, ['pan'], [0.5])  # valid a moment ago, now refused
        assert not result.success
        assert '0.3000' in result.message and 'nothing sent' in result.message
        # The refused move sent nothing: the commanded target is still the last move's.
        status = ros.wait_for_message(f'/{NODE}/status', GimbalStatus, timeout=15)
        assert status.axes[0].name == 'pan' and status.axes[0].target_position == 0.2
    finally:
        assert ros.set_parameter(NODE, 'position_max', [3.141592653589793, 1.5707963267948966]
                                 ).successful


def test_command_timeout_applies_to_a_running_jog(rig) -> None:
    ros, node = rig
    assert ros.set_parameter(NODE, 'command_timeout', 0.0).successful  # watchdog off
    try:
        ros.publish('joint_command', JointState(name=['tilt'], velocity=[0.1]))
        tilt(ros, lambda _, velocity: velocity > 0.05)  # the jog started
        # Well past the start-up timeout of 0.4 s (1.5 s at 0.1 rad/s) the jog still runs:
        # the 0 took effect.
        tilt(ros, lambda position, velocity: position > 0.15 and velocity > 0.05)
        # A (shorter) timeout set now stops the running jog without any new command.
        assert ros.set_parameter(NODE, 'command_timeout', 0.3).successful
        tilt(ros, lambda _, velocity: velocity == 0.0)  # the watchdog stopped it
        node.wait_for_output('expired (no joint_command for 0.3 s)')
    finally:
        ros.set_parameter(NODE, 'command_timeout', 0.4)
        ros.publish('joint_command', JointState(name=['tilt'], velocity=[0.0]))


def test_move_timeout_and_diagnostics_period_take_effect(rig) -> None:
    ros, _ = rig
    assert ros.set_parameter(NODE, 'move_timeout', 0.1).successful
    try:
        result, _, _ = move(ros, ['pan'], [-2.5])  # about 2 s at 1.5 rad/s
        assert not result.success
        assert result.message == 'not reached within move_timeout 0.1 s', result.message
    finally:
        assert ros.set_parameter(NODE, 'move_timeout', 60.0).successful
    assert ros.set_parameter(NODE, 'diagnostics_period', 0.1).successful
    try:
        ros.mean_stamp_gap('/diagnostics', DiagnosticArray, 1)
        assert ros.mean_stamp_gap('/diagnostics', DiagnosticArray, 5) < 0.5  # was 1 s
    finally:
        assert ros.set_parameter(NODE, 'diagnostics_period', 1.0).successful
