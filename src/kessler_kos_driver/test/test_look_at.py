"""~/look_at of kessler_kos_driver_node (process) against kessler_kos_sim (process).

The chain is slider -> pan -> tilt: look_at holds the slider where it is and aims pan and
tilt from the carriage. The simulator's default calibrated tilt range is 0..-40 rotations,
so this rig maps REP-103 tilt with a negative joint scale (device tilt counts downward
here) and narrows the node's tilt limits so that a low point is beyond them.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')

from gimbal_driver_common.sim_control import control_state
from gimbal_driver_common.testing import DomainLease, ManagedProcess, free_tcp_port
from gimbal_driver_common.testing.look_at import LookAtRig, LookAtSuite, look_at_rig_against

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
                '-p', f'joint_scales:=[{TWO_PI}, {TWO_PI}, {-TWO_PI}]',
                '-p', 'position_min:=[-1000.0, -1000.0, -0.8]'])

        with look_at_rig_against(PKG, domain, sim, start_node,
                                 lambda: motor_rotations(control_port)) as rig:
            yield rig


class TestLookAt(LookAtSuite):
    def test_look_at_moves_pan_and_tilt_and_holds_the_slider(
            self, look_at_rig: LookAtRig) -> None:
        slider = look_at_rig.device_state()['slider']
        look_at_rig.check.look_and_reach(math.pi / 2, LookAtSuite.UP)
        rotations = look_at_rig.device_state()
        assert rotations['pan'] == pytest.approx(0.25, abs=0.01)
        assert rotations['tilt'] == pytest.approx(-LookAtSuite.UP / TWO_PI, abs=0.01)
        assert rotations['slider'] == pytest.approx(slider, abs=1e-3)

    def test_look_at_outside_the_calibrated_range_is_refused_by_the_client_check(
            self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        check.look_and_reach(0.0, 0.0)  # from pan 0, -90 deg is nearer than +270 deg
        # pan -90 deg is inside the node's limits but below the pan motor's begin mark (0 rot)
        check.refused(check.point_for(-math.pi / 2, 0.0), 'calibrated range',
                      device_commands=look_at_rig.device_state)
