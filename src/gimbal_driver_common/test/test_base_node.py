"""The shared lifecycle base node, exercised through the reference virtual-gimbal driver.

Simulator and node run as separate processes (loopback DDS, a leased domain);
the test talks to the node over ROS and, where it must see the device side, to
the simulator over its own TCP protocol.
"""

from __future__ import annotations

import math
import signal

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import Transition
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_common.ros.testing import RosTestClient, find_diagnostic, joint_positions
from gimbal_driver_common.testing import DomainLease, ManagedProcess, free_tcp_port, wait_for
from gimbal_driver_common.virtual_gimbal import VirtualGimbalClient
from gimbal_msgs.action import Home, MoveTo
from gimbal_msgs.msg import GimbalStatus
from gimbal_msgs.srv import ClearPreset, GotoPreset, ListPresets, SetPreset, StartScan

pytestmark = pytest.mark.ros

PKG = 'gimbal_driver_common'
NODE = 'virtual_gimbal'


def start_sim(port: int) -> ManagedProcess:
    sim = ManagedProcess.ros(PKG, 'virtual_gimbal_sim', 0, ['--port', str(port)])
    sim.wait_for_output('listening')
    return sim


def start_node(domain: int, port: int, *params: str) -> ManagedProcess:
    args = ['--ros-args', '-p', f'port:={port}', '-p', 'reconnect_period:=0.2',
            '-p', 'diagnostics_period:=0.25', *[x for p in params for x in ('-p', p)]]
    return ManagedProcess.ros(PKG, 'virtual_gimbal_node', domain, args)


def device_state(port: int) -> list[float]:
    client = VirtualGimbalClient('127.0.0.1', port)
    client.open()
    try:
        return [float(w) for w in client.request('GET').split()[1:5]]
    finally:
        client.close()


def connection_status(array: DiagnosticArray) -> tuple[int, str] | None:
    status = find_diagnostic(array, NODE, 'connection')
    return (status.level[0], status.message) if status else None


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    lease = DomainLease()
    domain = lease.acquire()
    port = free_tcp_port()
    presets = tmp_path_factory.mktemp('presets') / 'presets.yaml'
    sim = start_sim(port)
    node = start_node(domain, port, f'presets_file:={presets}', 'command_timeout:=0.4')
    ros = RosTestClient(domain)
    try:
        ros.wait_for_message('joint_states', JointState, timeout=30)
        yield ros, port, presets, node
    finally:
        ros.close()
        node.stop()
        sim.stop()
        lease.release()


def move(ros: RosTestClient, names, values, relative=False, velocities=()):
    goal = MoveTo.Goal(joint_names=list(names), positions=list(values), relative=relative,
                       velocities=list(velocities))
    return ros.run_action(MoveTo, f'/{NODE}/move_to', goal, timeout=30)


def test_publishes_joint_states_status_and_diagnostics(rig) -> None:
    ros, _, _, _ = rig
    msg = ros.wait_for_message('joint_states', JointState)
    assert msg.name == ['pan', 'tilt'] and len(msg.velocity) == 2
    assert msg.header.stamp.sec > 0
    status = ros.wait_for_message(f'/{NODE}/status', GimbalStatus)
    assert status.connection == GimbalStatus.CONNECTION_CONNECTED
    assert status.serial_number == 'VG-0001' and [a.name for a in status.axes] == ['pan', 'tilt']
    diag = ros.wait_for_message('/diagnostics', DiagnosticArray,
                                lambda a: connection_status(a) is not None)
    assert connection_status(diag)[0] == 0
    assert all(s.hardware_id == 'VG-0001' for s in diag.status)


def test_move_to_reaches_target_and_joint_states_show_it(rig) -> None:
    ros, port, _, _ = rig
    result, _status, feedback = move(ros, ['pan', 'tilt'], [0.5, -0.3])
    assert result.success, result.message
    assert result.positions == pytest.approx([0.5, -0.3], abs=0.011)
    assert feedback, 'MoveTo publishes feedback while moving'
    msg = ros.wait_for_message('joint_states', JointState)
    assert joint_positions(msg)['pan'] == pytest.approx(0.5, abs=0.011)
    assert device_state(port)[0] == pytest.approx(0.5, abs=0.011)
    result, _, _ = move(ros, ['pan'], [-0.2], relative=True)
    assert result.success and result.positions[0] == pytest.approx(0.3, abs=0.011)


def test_move_to_refuses_out_of_range_and_unknown_joints(rig) -> None:
    ros, port, _, _ = rig
    before = device_state(port)
    result, _, _ = move(ros, ['pan'], [10.0])
    assert not result.success and 'outside' in result.message
    result, _, _ = move(ros, ['roll'], [0.0])
    assert not result.success and 'unknown joint' in result.message
    result, _, _ = move(ros, ['pan'], [0.0], velocities=[9.0])
    assert not result.success and 'velocity_max' in result.message
    assert device_state(port)[:2] == pytest.approx(before[:2], abs=1e-6)


def test_jog_stops_after_command_timeout(rig) -> None:
    ros, port, _, node = rig
    ros.publish('joint_command', JointState(name=['tilt'], velocity=[0.2]))
    wait_for(lambda: abs(device_state(port)[3]) > 0.1, 5, 'the tilt jog to start')
    # No further commands: the dead-man watchdog (0.4 s) must stop the axis.
    wait_for(lambda: device_state(port)[3] == 0.0, 5, 'the watchdog to stop the jog')
    node.wait_for_output('expired')


def test_unknown_joint_command_sends_nothing(rig) -> None:
    ros, port, _, node = rig
    before = device_state(port)
    # joint_command is keep-last 1: wait for each rejection before the next command.
    ros.publish('joint_command', JointState(name=['roll'], position=[0.1]))
    node.wait_for_output("unknown joint(s) ['roll']")
    ros.publish('joint_command', JointState(name=['pan'], position=[math.nan], velocity=[5.0]))
    node.wait_for_output('exceeds velocity_max')
    assert device_state(port)[:2] == pytest.approx(before[:2], abs=1e-6)


def test_stop_service_halts_a_move(rig) -> None:
    ros, port, _, _ = rig
    ros.publish('joint_command', JointState(name=['pan'], position=[-2.5], velocity=[0.3]))
    wait_for(lambda: abs(device_state(port)[2]) > 0.1, 5, 'the move to start')
    reply = ros.call(Trigger, f'/{NODE}/stop', Trigger.Request())
    assert reply.success, reply.message
    state = device_state(port)
    assert state[2] == 0.0 and state[0] > -2.4


def test_driver_side_presets_persist_in_yaml(rig) -> None:
    ros, port, presets_file, _ = rig
    ok = ros.call(SetPreset, f'/{NODE}/set_preset', SetPreset.Request(
        index=4, name='door', joint_names=['pan', 'tilt'], positions=[0.2, 0.1]))
    assert ok.success, ok.message
    bad = ros.call(SetPreset, f'/{NODE}/set_preset', SetPreset.Request(
        index=5, name='bad', joint_names=['pan'], positions=[99.0]))
    assert not bad.success and 'outside' in bad.message
    assert 'door' in presets_file.read_text()
    listed = ros.call(ListPresets, f'/{NODE}/list_presets', ListPresets.Request())
    assert [p.index for p in listed.presets] == [4]
    go = ros.call(GotoPreset, f'/{NODE}/goto_preset', GotoPreset.Request(index=4))
    assert go.success, go.message
    wait_for(lambda: device_state(port)[0] == pytest.approx(0.2, abs=1e-3), 10, 'preset reached')
    missing = ros.call(GotoPreset, f'/{NODE}/goto_preset', GotoPreset.Request(index=9))
    assert not missing.success and 'no preset 9' in missing.message
    cleared = ros.call(ClearPreset, f'/{NODE}/clear_preset', ClearPreset.Request(all=True))
    assert cleared.success
    assert ros.call(ListPresets, f'/{NODE}/list_presets', ListPresets.Request()).presets == []


def test_driver_side_sector_scan_and_stop(rig) -> None:
    ros, port, _, _ = rig
    bad = ros.call(StartScan, f'/{NODE}/start_scan', StartScan.Request(
        pattern='snake', pan_min=-0.2, pan_max=0.2, speed=1.0))
    assert not bad.success and 'sector' in bad.message
    ok = ros.call(StartScan, f'/{NODE}/start_scan', StartScan.Request(
        pattern='sector', pan_min=-0.2, pan_max=0.2, speed=1.2))
    assert ok.success, ok.message
    wait_for(lambda: device_state(port)[0] < -0.19, 10, 'pan to reach pan_min')
    wait_for(lambda: device_state(port)[0] > 0.19, 10, 'pan to reach pan_max')
    stop = ros.call(Trigger, f'/{NODE}/stop_scan', Trigger.Request())
    assert stop.success


def test_home_action(rig) -> None:
    ros, _, _, _ = rig
    move(ros, ['pan', 'tilt'], [0.3, 0.3])
    result, _, feedback = ros.run_action(Home, f'/{NODE}/home', Home.Goal(), timeout=30)
    assert result.success, result.message
    assert feedback and feedback[0].state
    bad, _, _ = ros.run_action(Home, f'/{NODE}/home', Home.Goal(joint_names=['roll']))
    assert not bad.success and 'unknown joint' in bad.message


def test_reconnects_after_device_loss_and_reports_it() -> None:
    with DomainLease() as domain:
        port = free_tcp_port()
        sim = start_sim(port)
        node = start_node(domain, port)
        with RosTestClient(domain) as ros:
            try:
                ros.wait_for_message('joint_states', JointState, timeout=30)
                sim.stop()
                diag = ros.wait_for_message(
                    '/diagnostics', DiagnosticArray,
                    lambda a: (connection_status(a) or (0, ''))[0] == 2)
                assert 'disconnected' in connection_status(diag)[1]
                assert 'disconnected' in ros.wait_for_diagnostic(NODE, 'connection').message
                stale = [s for s in diag.status if s.name == f'{NODE}: pan']
                assert stale and stale[0].level[0] == 3
                status = ros.wait_for_message(f'/{NODE}/status', GimbalStatus)
                assert status.connection != GimbalStatus.CONNECTION_CONNECTED
                sim = start_sim(port)
                ros.wait_for_message(
                    '/diagnostics', DiagnosticArray,
                    lambda a: (connection_status(a) or (2, ''))[0] == 0, timeout=20)
                ros.wait_for_message('joint_states', JointState, timeout=10)
                node.wait_for_output('reconnected')
            finally:
                node.stop()
                sim.stop()


def test_shutdown_stops_moving_axes_and_managed_bringup() -> None:
    with DomainLease() as domain:
        port = free_tcp_port()
        sim = start_sim(port)
        node = start_node(domain, port, 'autostart:=false', 'command_timeout:=0.0')
        try:
            with RosTestClient(domain) as ros:
                assert ros.lifecycle_state(NODE) == 'unconfigured'
                assert ros.lifecycle_transition(NODE, Transition.TRANSITION_CONFIGURE)
                assert ros.lifecycle_state(NODE) == 'inactive'
                reply = ros.call(Trigger, f'/{NODE}/reset_faults', Trigger.Request())
                assert not reply.success and 'not active' in reply.message
                assert ros.lifecycle_transition(NODE, Transition.TRANSITION_ACTIVATE)
                ros.publish('joint_command', JointState(name=['pan'], velocity=[0.3]))
                wait_for(lambda: device_state(port)[2] > 0.1, 5, 'the jog to start')
            node.send_signal(signal.SIGINT)
            node.process.wait(15)
            assert device_state(port)[2] == 0.0, 'a node that shuts down stops its axes'
        finally:
            node.stop()
            sim.stop()


def test_invalid_parameters_are_refused_at_startup() -> None:
    with DomainLease() as domain:
        node = start_node(domain, free_tcp_port(), 'position_min:=[-1.0, -1.0, -1.0]')
        node.process.wait(30)
        assert node.process.returncode == 2
        assert 'position_min has 3 values' in node.output()
        node = start_node(domain, free_tcp_port(), 'publish_rate:=0.0')
        node.process.wait(30)
        assert node.process.returncode == 2 and 'publish_rate' in node.output()
