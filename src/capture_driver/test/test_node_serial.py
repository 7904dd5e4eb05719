"""capture_driver_node over a serial line (the simulator's pseudo-terminal), as processes."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from capture_driver.sim import control
from gimbal_driver_testing import ManagedProcess, free_tcp_port, wait_for_ready
from gimbal_driver_testing.ros import driver_rig
from gimbal_msgs.action import MoveTo

pytestmark = pytest.mark.ros

PKG = 'capture_driver'


def connection_level(array: DiagnosticArray) -> bytes | None:
    for status in array.status:
        if status.name == 'capture_driver: connection':
            return status.level
    return None


def serial_node_parameters(sim: ManagedProcess) -> list[str]:
    """The node on the pseudo-terminal the simulator announced in its ready line."""
    tty = wait_for_ready(sim, 'capture_sim')['pty']
    return ['transport:=serial', f'serial_port:={tty}', 'publish_rate:=20.0',
            'reconnect_period:=0.3', 'diagnostics_period:=0.25', 'imu_rate:=0.0',
            'fix_rate:=0.0']


def test_node_over_serial_moves_and_survives_unplugging():
    control_port = free_tcp_port()
    with driver_rig(PKG, 'capture_sim', ['--port', '-1', '--pty', '--control-port',
                                         str(control_port), '--time-scale', '4'],
                    '{"ready": "capture_sim"', 'capture_driver_node',
                    serial_node_parameters) as started:
        ros = started.ros
        goal = MoveTo.Goal(joint_names=['pan', 'tilt'], positions=[0.2, 0.1])
        result, _, _ = ros.run_action(MoveTo, '/capture_driver/move_to', goal, timeout=40)
        assert result.success, result.message
        assert control(control_port, 'drop 1.0') == 'ok'
        ros.wait_for_message('/diagnostics', DiagnosticArray,
                             lambda a: connection_level(a) == b'\x02', timeout=15)
        ros.wait_for_message('/diagnostics', DiagnosticArray,
                             lambda a: connection_level(a) == b'\x00', timeout=30)
        msg = ros.wait_for_message('joint_states', JointState, timeout=15)
        assert dict(zip(msg.name, msg.position, strict=True))['pan'] == pytest.approx(
            0.2, abs=2e-3)
