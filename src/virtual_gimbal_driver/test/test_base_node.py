"""The shared lifecycle base node, exercised through the reference virtual-gimbal driver.

Simulator and node run as separate processes (loopback DDS, a leased domain);
the test talks to the node over ROS and, where it must see the device side, to
the simulator over its own TCP protocol.
"""

from __future__ import annotations

import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_testing import DomainLease, ManagedProcess, free_tcp_port, wait_for
from gimbal_driver_testing.ros import RosTestClient, find_diagnostic, joint_positions
from gimbal_msgs.action import MoveTo
from gimbal_msgs.msg import GimbalStatus
from gimbal_msgs.srv import StartScan
from virtual_gimbal_driver.client import VirtualGimbalClient

pytestmark = pytest.mark.ros

PKG = 'virtual_gimbal_driver'
NODE = 'virtual_gimbal_driver'


def start_sim(port: int) -> ManagedProcess:
    sim = ManagedProcess.ros(PKG, 'virtual_gimbal_sim', 0, ['--port', str(port)])
    sim.wait_for_output('{"ready": "virtual_gimbal_sim"')
    return sim


def start_node(domain: int, port: int, *params: str) -> ManagedProcess:
    args = ['--ros-args', '-p', f'port:={port}', '-p', 'reconnect_period:=0.2',
            '-p', 'diagnostics_period:=0.25', *[x for p in params for x in ('-p', p)]]
    return ManagedProcess.ros(PKG, 'virtual_gimbal_driver_node', domain, args)


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


def stamp_of(msg: JointState) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def test_move_to_reaches_target_and_joint_states_show_it(rig) -> None:
    ros, port, _, _ = rig
    result, _status, feedback = move(ros, ['pan', 'tilt'], [0.5, -0.3])
    done = time.time()  # the node stamps joint_states on this (the system) clock
    assert result.success, result.message
    assert result.positions == pytest.approx([0.5, -0.3], abs=0.011)
    assert feedback, 'MoveTo publishes feedback while moving'
    # the first sample read after the result: a loaded machine delivers older joint_states
    # (from before the move) after the result, and "received after" does not exclude them
    msg = ros.wait_for_message('joint_states', JointState, lambda m: stamp_of(m) >= done)
    assert joint_positions(msg)['pan'] == pytest.approx(0.5, abs=0.011)
    assert device_state(port)[0] == pytest.approx(0.5, abs=0.011)
    result, _, _ = move(ros, ['pan'], [-0.2], relative=True)
    assert result.success and result.positions[0] == pytest.approx(0.3, abs=0.011)












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
