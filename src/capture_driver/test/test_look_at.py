"""~/look_at of capture_driver_node (process) against capture_sim (process) over TCP.

Capture counts yaw clockwise, so joint_directions [-1, 1] negates pan: look_at works in
REP-103 joint space and the device sees the negated angle.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')

from capture_driver.sim import console_state
from gimbal_driver_testing import DomainLease, ManagedProcess, free_tcp_port
from gimbal_driver_testing.look_at import LookAtRig, LookAtSuite, look_at_rig_against

pytestmark = pytest.mark.ros

PKG = 'capture_driver'


@pytest.fixture(scope='module')
def look_at_rig():
    with DomainLease() as domain:
        port, control_port = free_tcp_port(), free_tcp_port()
        sim = ManagedProcess.ros(PKG, 'capture_sim', domain, [
            '--port', str(port), '--control-port', str(control_port), '--time-scale', '4'])

        def start_node() -> ManagedProcess:
            sim.wait_for_output('{"ready": "capture_sim"')
            return ManagedProcess.ros(PKG, 'capture_driver_node', domain, [
                '--ros-args', '-p', 'host:=127.0.0.1', '-p', f'port:={port}',
                '-p', 'publish_rate:=20.0', '-p', 'reconnect_period:=0.3',
                '-p', 'default_speed:=1.0', '-p', 'acceleration:=6.0',
                '-p', f'position_min:=[{-math.pi}, -0.8]'])

        with look_at_rig_against(PKG, domain, sim, start_node,
                                 lambda: console_state(control_port)['axes']) as rig:
            yield rig


class TestLookAt(LookAtSuite):
    def test_look_at_left_is_a_negative_device_pan(self, look_at_rig: LookAtRig) -> None:
        look_at_rig.check.look_and_reach(math.pi / 2, LookAtSuite.UP)
        axes = look_at_rig.device_state()
        assert axes['1']['position'] == pytest.approx(-90.0, abs=1.0)
        assert axes['2']['position'] == pytest.approx(math.degrees(LookAtSuite.UP), abs=1.0)
