"""Common parameters changed while the node runs (`ros2 param set`), on the virtual gimbal.

The node runs as a process against the simulator; the test sets parameters
through the node's /<node>/set_parameters service, as `ros2 param set` does,
and watches the effect on joint_states, the actions and the simulator.
"""

from __future__ import annotations

import pytest
from sensor_msgs.msg import JointState

from gimbal_driver_common.ros.testing import RosTestClient
from gimbal_driver_common.testing import DomainLease, ManagedProcess, free_tcp_port, wait_for
from gimbal_driver_common.virtual_gimbal import VirtualGimbalClient
from gimbal_msgs.action import MoveTo

pytestmark = pytest.mark.ros

PKG = 'gimbal_driver_common'
NODE = 'virtual_gimbal'


def device_state(port: int) -> list[float]:
    """pan, tilt, pan velocity, tilt velocity as the simulator holds them."""
    client = VirtualGimbalClient('127.0.0.1', port)
    client.open()
    try:
        return [float(w) for w in client.request('GET').split()[1:5]]
    finally:
        client.close()


def move(ros: RosTestClient, names, values):
    goal = MoveTo.Goal(joint_names=list(names), positions=list(values))
    return ros.run_action(MoveTo, f'/{NODE}/move_to', goal, timeout=30)


@pytest.fixture(scope='module')
def rig():
    lease = DomainLease()
    domain = lease.acquire()
    port = free_tcp_port()
    sim = ManagedProcess.ros(PKG, 'virtual_gimbal_sim', 0, ['--port', str(port)])
    sim.wait_for_output('listening')
    node = ManagedProcess.ros(PKG, 'virtual_gimbal_node', domain, [
        '--ros-args', '-p', f'port:={port}', '-p', 'reconnect_period:=0.2',
        '-p', 'command_timeout:=0.4'])
    ros = RosTestClient(domain)
    try:
        ros.wait_for_message('joint_states', JointState, timeout=30)
        yield ros, port, node
    finally:
        ros.close()
        node.stop()
        sim.stop()
        lease.release()


def test_publish_rate_changes_the_joint_states_rate(rig) -> None:
    ros, _, _ = rig
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
    ros, _, _ = rig
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
    ros, _, _ = rig
    refused = ros.set_parameter(NODE, 'joint_names', ['a', 'b'])
    assert not refused.successful and 'read-only' in refused.reason
    refused = ros.set_parameter(NODE, 'port', 1234)
    assert not refused.successful and 'needs reconfigure' in refused.reason
    assert "'port'" in refused.reason
    refused = ros.set_parameter(NODE, 'presets_file', '/tmp/elsewhere.yaml')
    assert not refused.successful and 'needs reconfigure' in refused.reason


def test_new_position_limit_rejects_a_move_that_was_valid(rig) -> None:
    ros, port, _ = rig
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
        assert abs(device_state(port)[0] - 0.2) < 0.02  # the refused move sent nothing
    finally:
        assert ros.set_parameter(NODE, 'position_max', [3.141592653589793, 1.5707963267948966]
                                 ).successful


def test_command_timeout_applies_to_a_running_jog(rig) -> None:
    ros, port, node = rig
    assert ros.set_parameter(NODE, 'command_timeout', 0.0).successful  # watchdog off
    try:
        ros.publish('joint_command', JointState(name=['tilt'], velocity=[0.1]))
        wait_for(lambda: abs(device_state(port)[3]) > 0.05, 10, 'the tilt jog to start')
        # Well past the start-up timeout of 0.4 s the jog still runs: the 0 took effect.
        node.wait_for_output("parameter 'command_timeout' set to 0.0")
        wait_for(lambda: abs(device_state(port)[1]) > 0.15, 20, 'tilt to jog past 0.15 rad')
        assert abs(device_state(port)[3]) > 0.05
        # A (shorter) timeout set now stops the running jog without any new command.
        assert ros.set_parameter(NODE, 'command_timeout', 0.3).successful
        wait_for(lambda: device_state(port)[3] == 0.0, 10, 'the watchdog to stop the jog')
        node.wait_for_output('expired (no joint_command for 0.3 s)')
    finally:
        ros.set_parameter(NODE, 'command_timeout', 0.4)
        ros.publish('joint_command', JointState(name=['tilt'], velocity=[0.0]))
