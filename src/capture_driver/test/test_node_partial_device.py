"""capture_driver_node as a process against controllers that answer, but not as the document
says (issue 26), capture_sim as a process in two modes:

* third-party: knows motion, load position and speed, voltage, current, the motor error
  register and COM_Connect, and answers ACK 0x06 to every other opcode, getters included
  (``--only third-party --ack-unknown``);
* partial: knows COM_Connect, the joint poll and the motion set-up without MOT_SetTum, and
  answers NACK 0xA6 to the rest (``--only partial``).

With default parameters (but the link, and a generous ``request_timeout``) the node
reaches active, joint_states flow, a move and a joint_command are carried out, the
diagnostics name what the device did not answer, identity reads "unknown", and nothing in
the log says "silent". Waits are "up to a timeout", never timing assertions.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Log
from sensor_msgs.msg import Imu, JointState

from capture_driver.sim import console_state as sim_state
from gimbal_driver_testing.ros import joint_positions
from gimbal_msgs.action import MoveTo
from gimbal_msgs.msg import GimbalStatus

pytestmark = pytest.mark.ros

NODE = 'capture_driver'
OK = b'\x00'
MODES = {
    'third-party': ['--only', 'third-party', '--ack-unknown'],
    'partial': ['--only', 'partial'],
}
#: s: the node's ``request_timeout``, as ``ANSWER_TIMEOUT_S`` of the in-process twin of this
#: test (``test_partial_device.py``): the simulator answers every request at once, so no reply
#: waits it out unless the machine holds it up (one came later than the default 0.5 s in a
#: pinned run and counted as a timeout, docs/testing.md); an answer of the wrong kind is told
#: at once, whatever the timeout
ANSWER_TIMEOUT_S = 5.0
#: what the device was asked at connect and in the status poll and does not answer with data
NOT_ANSWERED = ('COM_GetSn', 'COM_GetFw', 'COM_GetHw', 'COM_GetPn', 'IMU_IsReadyImu',
                'GPS_isConnectedGPS', 'MOT_SrlRegister', 'ERR_CaptureSystemRegister')


def device_status(array: DiagnosticArray):
    return next((s for s in array.status if s.name == f'{NODE}: device'), None)


def names_everything(mode: str):
    def match(array: DiagnosticArray) -> bool:
        status = device_status(array)
        keys = {kv.key for kv in status.values} if status else set()
        wanted = {f'unsupported.{name}' for name in NOT_ANSWERED}
        if mode == 'partial':
            wanted.add('unsupported.MOT_SetTum')
        return wanted <= keys
    return match


def at(positions: dict[str, float]):
    return lambda m: all(abs(joint_positions(m).get(j, math.inf) - p) < 2e-3
                         for j, p in positions.items())


@pytest.mark.parametrize('mode', MODES)
def test_a_partial_controller_is_driven_as_far_as_it_goes(capture_rig, mode):
    with capture_rig(['--time-scale', '4', *MODES[mode]], [f'request_timeout:={ANSWER_TIMEOUT_S}'],
                     record=[('/rosout', Log)], node_log_tail=6000) as (rig, control_port):
        ros = rig.ros
        status_messages = ros.subscribe(f'/{NODE}/status', GimbalStatus)
        ros.subscribe(f'/{NODE}/imu', Imu)  # a subscriber: the IMU would be read if it were there
        assert ros.lifecycle_state(NODE) == 'active'
        ros.wait_for_message('joint_states', JointState, timeout=30)

        goal = MoveTo.Goal(joint_names=['pan', 'tilt'], positions=[0.3, -0.15])
        result, _, _ = ros.run_action(MoveTo, f'/{NODE}/move_to', goal, timeout=40)
        assert result.success, result.message
        ros.wait_for_message('joint_states', JointState, at({'pan': 0.3, 'tilt': -0.15}),
                             timeout=30)
        axes = sim_state(control_port)['axes']
        assert axes['1']['position'] == pytest.approx(-math.degrees(0.3), abs=0.1)
        ros.publish('joint_command', JointState(name=['pan'], position=[-0.2]))
        ros.wait_for_message('joint_states', JointState, at({'pan': -0.2}), timeout=30)

        array = ros.wait_for_message('/diagnostics', DiagnosticArray, names_everything(mode),
                                     timeout=30)
        device = device_status(array)
        values = {kv.key: kv.value for kv in device.values}
        how = 'answered ACK, expected data' if mode == 'third-party' else 'answered NACK 0xA6'
        assert how in values['unsupported.COM_GetFw'], values
        assert device.level == OK, (device.message, values)
        assert 'device does not know: ' in device.message
        assert device.message.count('COM_GetFw') == 1  # said once
        assert values['link.timeouts'] == '0', values  # no reply waited out
        connection = next(s for s in array.status if s.name == f'{NODE}: connection')
        assert connection.level == OK
        assert connection.hardware_id.startswith(
            'capture-pnunknown-snunknown-hwunknown-fwunknown@tcp://127.0.0.1:')
        conn_values = {kv.key: kv.value for kv in connection.values}
        assert (conn_values['serial_number'], conn_values['firmware']) == ('unknown', 'unknown')
        for joint in ('pan', 'tilt'):
            joint_status = next(s for s in array.status if s.name == f'{NODE}: {joint}')
            assert joint_status.level == OK, joint_status.message

        status = ros.wait_for_message(f'/{NODE}/status', GimbalStatus,
                                      lambda m: m.serial_number == 'unknown', timeout=15)
        assert status.firmware_version == 'unknown' and 'unknown' in status.device_model
        assert status_messages

        # said once: the client names each command it stops sending once, the node the
        # identity once; nothing anywhere calls this device silent
        output = rig.node.output()
        assert output.count('COM_GetFw: the device does not support it') == 1, output
        if mode == 'partial':
            assert output.count('MOT_SetTum: the device does not support it') == 1, output
        assert output.count('identity: serial number, firmware, hardware, part number '
                            'unknown') == 1, output
        assert 'silent' not in output.lower()
        assert not [m.msg for m in rig.recorded['/rosout'] if 'silent' in m.msg.lower()]
        state = sim_state(control_port)['requests_by_command']
        assert state.get('IMU_GetRoll', 0) == 0  # no IMU: never read, though subscribed
        # at connect only: an 0xA6 once; an ACK twice (a getter is retried once)
        assert state.get('COM_GetFw', 0) == (2 if mode == 'third-party' else 1)
