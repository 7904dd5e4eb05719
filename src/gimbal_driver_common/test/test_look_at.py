"""~/look_at of the reference virtual-gimbal driver: node process against its simulator."""

from __future__ import annotations

import math

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')
from lifecycle_msgs.msg import Transition
from sensor_msgs.msg import JointState

from gimbal_driver_common.ros.look_at_testing import LookAtCheck, installed_description
from gimbal_driver_common.ros.testing import RosTestClient
from gimbal_driver_common.testing import DomainLease, ManagedProcess, free_tcp_port
from gimbal_driver_common.virtual_gimbal import VirtualGimbalClient

pytestmark = pytest.mark.ros

PKG = 'gimbal_driver_common'
NODE = 'virtual_gimbal'
TILT_MIN = -0.8  # rad: narrower than the default so a low point is beyond the limit


def device_state(port: int) -> str:
    """The simulator's state line: positions, velocities, moving bits, faults."""
    client = VirtualGimbalClient('127.0.0.1', port)
    client.open()
    try:
        return client.request('GET')
    finally:
        client.close()


@pytest.fixture(scope='module')
def rig():
    with DomainLease() as domain:
        port = free_tcp_port()
        sim = ManagedProcess.ros(PKG, 'virtual_gimbal_sim', 0, ['--port', str(port)])
        node = None
        try:
            sim.wait_for_output('listening')
            node = ManagedProcess.ros(PKG, 'virtual_gimbal_node', domain, [
                '--ros-args', '-p', f'port:={port}', '-p', 'reconnect_period:=0.2',
                '-p', f'position_min:=[{-math.pi}, {TILT_MIN}]'])
            with RosTestClient(domain) as ros:
                ros.wait_for_message('joint_states', JointState, timeout=30)
                description = installed_description(PKG, 'virtual_gimbal.urdf')
                yield LookAtCheck(ros, NODE, description), port
        finally:
            if node is not None:
                node.stop()
            sim.stop()


def test_look_at_straight_ahead(rig):
    check, _ = rig
    check.look_and_reach(0.0, 0.0)


def test_look_at_to_the_left(rig):
    check, _ = rig
    check.look_and_reach(math.pi / 2, 0.0)


def test_look_at_up(rig):
    check, _ = rig
    check.look_and_reach(0.0, 0.5)


def test_look_at_beyond_the_tilt_limit_is_refused_and_sends_nothing(rig):
    check, port = rig
    before = device_state(port)
    check.refused(check.point_for(0.0, -1.2), 'position_min')
    assert device_state(port) == before


def test_look_at_refuses_other_frames_bad_speeds_and_points(rig):
    check, _ = rig
    ahead = check.point_for(0.0, 0.0)
    check.refused(ahead, "not the device's base frame 'base_link'", frame='map')
    check.refused(ahead, 'exceeds velocity_max', speed=5.0)
    check.refused((math.nan, 0.0, 0.0), 'not a finite point')


def test_look_at_with_an_empty_frame_and_a_speed(rig):
    check, _ = rig
    result, _, _ = check.look_at(check.point_for(-0.3, 0.2), frame='', speed=0.5)
    assert result.success, result.message
    assert list(result.positions) == pytest.approx([-0.3, 0.2], abs=0.02)


def test_look_at_asks_the_motion_refusal_first(rig):
    check, port = rig
    point = check.point_for(0.4, 0.0)  # joint_states stop while inactive
    assert check.ros.lifecycle_transition(NODE, Transition.TRANSITION_DEACTIVATE)
    try:
        before = device_state(port)
        result, _, _ = check.look_at(point)
        assert not result.success
        assert 'nothing sent' in result.message and 'not active' in result.message
        assert device_state(port) == before
    finally:
        assert check.ros.lifecycle_transition(NODE, Transition.TRANSITION_ACTIVATE)
    check.look_and_reach(0.4, 0.0)
