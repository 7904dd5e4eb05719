"""A healthy device with default parameters shows every diagnostics status OK, also when it
does not know an opcode the node polls on its own (GPS_GetLatitude is a low-confidence
reconstruction): the poll stops after the device's 0xA6, the diagnostics name the command
once, and the device's protocol-error flag does not stay set.

Node and simulator run as processes; waits are "up to a timeout", never timing assertions.
"""

from __future__ import annotations

import contextlib
import json
import socket
from collections.abc import Iterator

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState, NavSatFix

from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance_rig import frequency_level_fits
from gimbal_driver_testing.ros import RosTestClient

pytestmark = pytest.mark.ros

PKG = 'capture_driver'
NODE = 'capture_driver'
OK = b'\x00'


def sim_state(port: int) -> dict:
    with socket.create_connection(('127.0.0.1', port), timeout=5.0) as sock:
        stream = sock.makefile('rw')
        stream.write('state\n')
        stream.flush()
        answer = stream.readline().strip()
    assert answer.startswith('ok '), answer
    return json.loads(answer[3:])


@pytest.fixture
def default_node(capture_rig):
    """Simulator with ``sim_args`` and a node with default parameters (but host/port)."""

    @contextlib.contextmanager
    def start(sim_args: list[str]) -> Iterator[tuple[RosTestClient, int]]:
        with capture_rig(sim_args, node_log_tail=4000) as (started, control_port):
            # the GPS fix is read only while ~/fix has a subscriber, as a user's would be
            started.ros.subscribe(f'/{NODE}/fix', NavSatFix)
            yield started.ros, control_port

    return start


def all_ok(array: DiagnosticArray) -> bool:
    """Every part OK; joint_states frequency measured and at the level its own rate gives
    (a node that 8 test workers on 2 cores starve really publishes below its rate, and WARN
    is then true: frequency_level_fits)."""
    mine = [s for s in array.status if s.name.startswith(f'{NODE}:')]
    names = {s.name.split(': ', 1)[1] for s in mine}
    return {'connection', 'joint_states frequency', 'pan', 'tilt', 'device'} <= names and all(
        (s.message != 'measuring' and frequency_level_fits(s))
        if s.name.endswith(': joint_states frequency') else s.level == OK for s in mine)


def device_status(array: DiagnosticArray):
    return next(s for s in array.status if s.name == f'{NODE}: device')


def test_healthy_device_with_default_parameters_is_all_ok(default_node):
    with default_node([]) as (ros, control_port):
        ros.wait_for_message('joint_states', JointState, timeout=30)
        array = ros.wait_for_message('/diagnostics', DiagnosticArray, all_ok, timeout=30)
        device = device_status(array)
        assert not any(kv.key.startswith(('unsupported.', 'wrong_reply.', 'identity.'))
                       for kv in device.values)
        assert 'does not know' not in device.message
        wait_for(lambda: sim_state(control_port)['requests_by_command'].get(
            'GPS_GetLatitude', 0) >= 1, 15.0, 'the fix poll (fix_rate 1 Hz) to read the GPS')
        # every part OK again after the fix poll: a GPS getter the device did not answer
        # would leave a lasting WARN (unsupported.*)
        array = ros.wait_for_message('/diagnostics', DiagnosticArray, all_ok, timeout=30)
        assert not any(kv.key.startswith(('unsupported.', 'wrong_reply.'))
                       for kv in device_status(array).values)


def test_device_without_gps_latitude_stops_that_poll_and_stays_ok(default_node):
    """GPS_GetLatitude (low confidence) and COM_GetHw unknown to the device."""
    with default_node(
        ['--unknown', 'GPS_GetLatitude', '--unknown', 'COM_GetHw']) as (ros, control_port):
        ros.wait_for_message('joint_states', JointState, timeout=30)
        array = ros.wait_for_message(
            '/diagnostics', DiagnosticArray,
            lambda a: all_ok(a) and 'GPS_GetLatitude' in device_status(a).message, timeout=30)
        device = device_status(array)
        mentions = [kv for kv in device.values if 'GPS_GetLatitude' in kv.key]
        assert [kv.key for kv in mentions] == ['unsupported.GPS_GetLatitude']
        assert 'Opcode not Recognized' in mentions[0].value
        assert device.message.count('GPS_GetLatitude') == 1
        # identity: what the device answers ends in hardware_id, the rest reads "unknown"
        connection = next(s for s in array.status if s.name == f'{NODE}: connection')
        assert connection.hardware_id == 'capture-pnCAP-PT2-SIM-sn24017-hwunknown-fw2.24.0'
        assert 'unsupported.COM_GetHw' in {kv.key for kv in device.values}
        first = sim_state(control_port)['requests_by_command']
        # Several more fix periods (1 s by default): the poll stays stopped, the device
        # status stays OK (its protocol-error flag is not raised again).
        for _ in range(4):
            array = ros.wait_for_message('/diagnostics', DiagnosticArray, timeout=15)
            assert all_ok(array), [(s.name, s.level, s.message) for s in array.status]
        later = sim_state(control_port)['requests_by_command']
        assert first['GPS_GetLatitude'] == later['GPS_GetLatitude'] == 1
        assert later.get('GPS_PositionReady', 0) == first.get('GPS_PositionReady', 0)
        assert later['MOT_GetLoadPosition'] > first['MOT_GetLoadPosition']  # still polling
