"""~/look_at of the reference virtual-gimbal driver: node process against its simulator."""

from __future__ import annotations

import math

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')
from lifecycle_msgs.msg import Transition

from gimbal_driver_testing import DomainLease, ManagedProcess, free_tcp_port
from gimbal_driver_testing.look_at import (
    LookAtRig,
    LookAtSuite,
    installed_description,
    look_at_rig_against,
)
from gimbal_msgs.action import LookAt
from virtual_gimbal_driver.client import VirtualGimbalClient

pytestmark = pytest.mark.ros

PKG = 'virtual_gimbal_driver'
NODE = 'virtual_gimbal_driver'
GOAL_CANCELED = 5


def device_state(port: int) -> str:
    """The simulator's state line: positions, velocities, moving bits, faults."""
    client = VirtualGimbalClient('127.0.0.1', port)
    client.open()
    try:
        return client.request('GET')
    finally:
        client.close()


@pytest.fixture(scope='module')
def look_at_rig():
    with DomainLease() as domain:
        port = free_tcp_port()
        sim = ManagedProcess.ros(PKG, 'virtual_gimbal_sim', 0, ['--port', str(port)])

        def start_node() -> ManagedProcess:
            sim.wait_for_output('{"ready": "virtual_gimbal_sim"')
            return ManagedProcess.ros(PKG, 'virtual_gimbal_driver_node', domain, [
                '--ros-args', '-p', f'port:={port}', '-p', 'reconnect_period:=0.2',
                '-p', f'position_min:=[{-math.pi}, -0.8]'])

        with look_at_rig_against(PKG, domain, sim, start_node, lambda: device_state(port),
                                 node=NODE, description=installed_description(
                                     PKG, 'virtual_gimbal_driver.urdf')) as rig:
            yield rig


class TestLookAt(LookAtSuite):
    def test_look_at_refuses_bad_speeds_and_points(self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        ahead = check.point_for(0.0, 0.0)
        check.refused(ahead, 'exceeds velocity_max', speed=5.0,
                      device_commands=look_at_rig.device_state)
        check.refused((math.nan, 0.0, 0.0), 'not a finite point')

    def test_look_at_with_an_empty_frame_and_a_speed(self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        result, _, _ = check.look_at(check.point_for(-0.3, 0.2), frame='', speed=0.5)
        assert result.success, result.message
        assert list(result.positions) == pytest.approx([-0.3, 0.2], abs=0.02)

    def test_look_at_asks_the_motion_refusal_first(self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        point = check.point_for(0.4, 0.0)  # joint_states stop while inactive
        assert check.ros.lifecycle_transition(NODE, Transition.TRANSITION_DEACTIVATE)
        try:
            before = look_at_rig.device_state()
            result, _, _ = check.look_at(point)
            assert not result.success
            assert 'nothing sent' in result.message and 'not active' in result.message
            assert look_at_rig.device_state() == before
        finally:
            assert check.ros.lifecycle_transition(NODE, Transition.TRANSITION_ACTIVATE)
        check.look_and_reach(0.4, 0.0)

    def test_look_at_cancel_stops_the_axes(self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        goal_point = check.point_for(-2.0, 0.3)  # 2+ rad away at 0.2 rad/s: 10 s or more
        goal = LookAt.Goal(speed=0.2)
        goal.target.header.frame_id = 'base_link'
        goal.target.point.x, goal.target.point.y, goal.target.point.z = goal_point
        result, status, _ = check.ros.run_action(
            LookAt, f'/{NODE}/look_at', goal, timeout=60, cancel_after=1.0)
        assert status == GOAL_CANCELED
        assert not result.success and result.message == 'cancelled'
        assert result.positions[0] > -2.0 + 0.1  # stopped on the way
