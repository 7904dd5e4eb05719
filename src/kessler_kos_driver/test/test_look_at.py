"""~/look_at of kessler_kos_driver_node (process) against kessler_kos_sim (process).

The chain is slider -> pan -> tilt: look_at holds the slider where it is and aims pan and
tilt from the carriage, in SI through calibrated spans: the pan's begin mark is a quarter
turn right (-pi/2 .. 3pi/2 over the simulator's 0..100 rotations, so a look to the back
right is inside the node's +-pi limits but not the calibrated range), the tilt is
-pi/2 .. pi/2 over 0..-40 rotations (the motor counts down as the tilt rises), and the
node's tilt limits are narrowed so that a low point is beyond them.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')

from gimbal_driver_common.sim_control import control_state
from gimbal_driver_testing import DomainLease, ManagedProcess, free_tcp_port
from gimbal_driver_testing.look_at import LookAtRig, LookAtSuite, look_at_rig_against

pytestmark = pytest.mark.ros

PKG = 'kessler_kos_driver'
PASSWORD = 'Zq8-kos-secret'
TWO_PI = 2 * math.pi


def motor_rotations(control_port: int) -> dict[str, float]:
    """Role -> position in motor rotations, from the simulator's ``state`` answer."""
    return {role: axis['position'] for role, axis in control_state(control_port)['axes'].items()}


@pytest.fixture(scope='module')
def look_at_rig():
    with DomainLease() as domain:
        port, control_port = free_tcp_port(), free_tcp_port()
        sim = ManagedProcess.ros(PKG, 'kessler_kos_sim', domain, [
            '--port', str(port), '--control-port', str(control_port), '--discovery-port', '0',
            '--password', PASSWORD, '--precalibrated', '--time-scale', '2'])

        def start_node() -> ManagedProcess:
            sim.wait_for_output('{"ready": "kessler_kos_sim"')
            return ManagedProcess.ros(PKG, 'kessler_kos_driver_node', domain, [
                '--ros-args', '-p', 'host:=127.0.0.1', '-p', f'port:={port}',
                '-p', f'password:={PASSWORD}', '-p', 'reconnect_period:=0.2',
                '-p', 'publish_rate:=20.0',
                '-p', f'calibrated_spans:=[1.5, {TWO_PI}, {math.pi}]',
                '-p', f'joint_offsets:=[0.0, {-math.pi / 2}, {-math.pi / 2}]',
                '-p', f'position_min:=[0.0, {-math.pi}, -0.8]'])

        with look_at_rig_against(PKG, domain, sim, start_node,
                                 lambda: motor_rotations(control_port)) as rig:
            yield rig


class TestLookAt(LookAtSuite):
    def test_look_at_moves_pan_and_tilt_and_holds_the_slider(
            self, look_at_rig: LookAtRig) -> None:
        slider = look_at_rig.device_state()['slider']
        look_at_rig.check.look_and_reach(math.pi / 2, LookAtSuite.UP)
        rotations = look_at_rig.device_state()
        # pan: (pi/2 + pi/2) / 2pi of 100 rotations; tilt: (UP + pi/2) / pi of -40
        assert rotations['pan'] == pytest.approx(50.0, abs=0.02)
        assert rotations['tilt'] == pytest.approx(
            -40.0 * (LookAtSuite.UP + math.pi / 2) / math.pi, abs=0.02)
        assert rotations['slider'] == pytest.approx(slider, abs=1e-3)

    def test_look_at_outside_the_calibrated_range_is_refused_in_si(
            self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        check.look_and_reach(0.0, 0.0)
        # pan -135 deg is inside the node's +-pi limits but right of the begin mark (-90 deg)
        result = check.refused(check.point_for(-3 * math.pi / 4, 0.0), 'calibrated range',
                               device_commands=look_at_rig.device_state)
        assert '[-1.5708, 4.7124]' in result.message, result.message
