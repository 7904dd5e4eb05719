"""~/look_at of capture_driver_node (process) against capture_sim (process) over TCP.

Capture counts yaw clockwise, so joint_directions [-1, 1] negates pan: look_at works in
REP-103 joint space and the device sees the negated angle.
"""

from __future__ import annotations

import json
import math
import socket

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')
from sensor_msgs.msg import JointState

from gimbal_driver_common.ros.look_at_testing import LookAtCheck, installed_description
from gimbal_driver_common.ros.testing import RosTestClient
from gimbal_driver_common.testing import DomainLease, ManagedProcess, free_tcp_port

pytestmark = pytest.mark.ros

PKG = 'capture_driver'
NODE = 'capture_driver'
TILT_MIN = -0.8  # rad: narrower than the default so a low point is beyond the limit


def sim_state(port: int) -> dict:
    with socket.create_connection(('127.0.0.1', port), timeout=5.0) as sock:
        stream = sock.makefile('rw')
        stream.write('state\n')
        stream.flush()
        answer = stream.readline().strip()
    assert answer.startswith('ok '), answer
    return json.loads(answer[3:])


@pytest.fixture(scope='module')
def rig():
    with DomainLease() as domain:
        port, control_port = free_tcp_port(), free_tcp_port()
        sim = ManagedProcess.ros(PKG, 'capture_sim', domain, [
            '--port', str(port), '--control-port', str(control_port), '--time-scale', '4'])
        node = None
        try:
            sim.wait_for_output('capture_sim ready')
            node = ManagedProcess.ros(PKG, 'capture_driver_node', domain, [
                '--ros-args', '-p', 'host:=127.0.0.1', '-p', f'port:={port}',
                '-p', 'publish_rate:=20.0', '-p', 'reconnect_period:=0.3',
                '-p', 'default_speed:=1.0', '-p', 'acceleration:=6.0',
                '-p', f'position_min:=[{-math.pi}, {TILT_MIN}]'])
            with RosTestClient(domain) as ros:
                ros.wait_for_message('joint_states', JointState, timeout=30)
                yield LookAtCheck(ros, NODE, installed_description(PKG)), control_port
        finally:
            if node is not None:
                node.stop()
            sim.stop()


def test_look_at_straight_ahead(rig):
    check, _ = rig
    check.look_and_reach(0.0, 0.0)


def test_look_at_to_the_left_turns_the_device_clockwise_axis_negative(rig):
    check, control_port = rig
    check.look_and_reach(math.pi / 2, 0.0)
    axes = sim_state(control_port)['axes']
    assert axes['1']['position'] == pytest.approx(-90.0, abs=1.0)  # device pan, deg
    assert axes['2']['position'] == pytest.approx(0.0, abs=1.0)


def test_look_at_up(rig):
    check, control_port = rig
    check.look_and_reach(0.0, 0.5)
    assert sim_state(control_port)['axes']['2']['position'] == pytest.approx(
        math.degrees(0.5), abs=1.0)


def test_look_at_beyond_the_tilt_limit_is_refused_and_sends_nothing(rig):
    check, control_port = rig
    before = sim_state(control_port)['axes']
    check.refused(check.point_for(0.0, -1.2), 'position_min')
    after = sim_state(control_port)['axes']
    assert [a['velocity'] for a in after.values()] == [0.0] * len(after)
    assert after['2']['position'] == before['2']['position']


def test_look_at_in_another_frame_is_refused(rig):
    check, _ = rig
    check.refused(check.point_for(0.0, 0.0), 'transform the point first', frame='odom')
