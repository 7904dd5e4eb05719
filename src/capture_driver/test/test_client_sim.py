"""The client against the simulator over the real transports (TCP loopback and a pty).

No timing assertions: tests wait *up to* a timeout for a condition.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from typing import Any

import pytest

from capture_driver.client import CaptureClient
from capture_driver.errors import DeviceNack, DeviceTimeout, NotConnected
from capture_driver.protocol import BY_OPCODE, COMMANDS, GeoPoint, ProtocolError, ReplyCode
from capture_driver.protocol.geometry import aim_at
from capture_driver.protocol.registers import CMER, REGISTERS, SRL
from capture_driver.sim import CaptureSimulator, PedestalModel
from gimbal_driver_common.link_lock import LinkLock
from gimbal_driver_common.sim_control import read_ready_line
from gimbal_driver_common.transport import SerialStream, TcpStream
from gimbal_driver_testing import wait_for

#: s a request waits for its answer unless the test is about timeouts (it sets its own): the
#: simulator shares this process, and on a loaded machine a pty answer can take 0.5 s
REQUEST_TIMEOUT = 3.0
#: s for a test whose requests go unanswered on purpose (a lost reply, a dropped request)
LOST_TIMEOUT = 0.3


@pytest.fixture
def sim():
    simulator = CaptureSimulator(PedestalModel(time_scale=8.0), tcp_port=0, pty=True).start()
    yield simulator
    simulator.stop()


def tcp_client(sim, **kwargs) -> CaptureClient:
    kwargs.setdefault('timeout', REQUEST_TIMEOUT)
    return CaptureClient(lambda: TcpStream('127.0.0.1', sim.tcp.port), **kwargs)


def pty_client(sim, **kwargs) -> CaptureClient:
    kwargs.setdefault('timeout', REQUEST_TIMEOUT)
    return CaptureClient(lambda: SerialStream(sim.pty.port_name), expect_greeting=False,
                         **kwargs)


@pytest.fixture(params=['tcp', 'pty'])
def client(request, sim):
    make = tcp_client if request.param == 'tcp' else pty_client
    c = make(sim)
    c.connect()
    yield c
    c.stop()


def settle(client, axis, target, tolerance=1e-3, timeout=10.0):
    def reached():
        position, speed, _ = client.read_axis(axis)
        return abs(position - target) <= tolerance and speed == 0.0

    wait_for(reached, timeout, f'axis {axis} at {target}')


def test_handshake_uses_the_greeting_opcode(sim):
    c = tcp_client(sim)
    c.connect()
    first = sim.model.requests[0]
    assert first.opcode == COMMANDS['COM_Connect'].opcode
    assert c.identity().serial_number == '24017'
    c.close()


def test_commands_before_handshake_are_refused(sim):
    stream = TcpStream('127.0.0.1', sim.tcp.port)
    stream.open()
    try:
        stream.write(COMMANDS['MOT_GetLoadPosition'].encode(1))
        received = bytearray()
        wait_for(lambda: received.extend(stream.read(64, 0.1)) or b'\xa6' in received, 5.0,
                 'NACK 0xA6')
    finally:
        stream.close()


def test_absolute_move_and_registers_follow_motion(client):
    client.move_absolute(1, 20.0, 60.0, 200.0)
    saw_moving = False
    for _ in range(200):
        srl = client.request('MOT_SrlRegister', 1)
        if not srl & (1 << 10):
            saw_moving = True
            break
    settle(client, 1, 20.0)
    assert saw_moving
    regs = client.registers(1)
    flags = {a.flag.name for a in SRL.decode(regs['SRL'])}
    assert {'motion_complete', 'axis_on'} <= flags
    assert client.request('MOT_GetPositionErr', 1) == 0.0


def test_relative_move_in_position_mode(client):
    client.move_absolute(2, 10.0, 60.0, 200.0)
    settle(client, 2, 10.0)
    for name, value in (('MOT_SetPositionMode', None), ('MOT_SetPositionRelative', None),
                        ('MOT_SetSpeed', 50.0), ('MOT_SendPosition', -4.0), ('MOT_Update', None)):
        client.request(name, 2, value)
    settle(client, 2, 6.0)


def test_jog_then_stop(client):
    client.jog(1, -30.0, 300.0)
    wait_for(lambda: client.read_axis(1)[1] < -1.0, 5.0, 'jog speed')
    client.stop_axis(1)
    wait_for(lambda: client.read_axis(1)[1] == 0.0, 5.0, 'stopped')


def test_software_limit_stops_the_axis(client):
    client.request('SWLS_SetNegSWLS', 1, -10.0)
    client.request('SWLS_SetPosSWLS', 1, 10.0)
    client.request('SWLS_ActivateSWLS', 1, 1)
    client.move_absolute(1, 40.0, 60.0, 300.0)
    wait_for(lambda: client.read_axis(1)[0] == pytest.approx(10.0), 10.0, 'at the limit')
    active = {a.flag.name for a in CMER.decode(client.request('ERR_CaptureMotorErrorRegister', 1))}
    assert 'software_positive_limit' in active


def test_emergency_stop_blocks_motion(client):
    client.request('MOT_SetEmgStopAxes', None, 1)
    assert client.request('MOT_GetEmgStopAxes') is True
    with pytest.raises(DeviceNack) as info:
        client.move_absolute(1, 5.0, 10.0, 100.0)
    assert info.value.code == ReplyCode.INVALID_COMMAND
    assert 'Emergency stop' in str(info.value)  # the controller's reason is attached
    client.request('MOT_SetEmgStopAxes', None, 0)
    client.move_absolute(1, 5.0, 30.0, 100.0)
    settle(client, 1, 5.0)


def test_homing_sets_and_clears_the_homing_bit(client, sim):
    sim.model.set_pose(1, 25.0)
    client.request('MOT_Homing', 1)
    assert client.request('MOT_SrlRegister', 1) & (1 << 8)
    wait_for(lambda: not client.request('MOT_SrlRegister', 1) & (1 << 8), 10.0, 'homing done')
    assert client.read_axis(1)[0] == 0.0
    assert client.request('ERR_OperationRegister', 1) == 0


def test_injected_fault_and_reset(client, sim):
    client.jog(1, 20.0, 300.0)
    sim.model.inject_fault(1, 'over_current')
    active = {a.flag.name for a in CMER.decode(client.request('ERR_CaptureMotorErrorRegister', 1))}
    assert {'fault', 'over_current'} <= active
    csr = client.request('ERR_CaptureSystemRegister')
    assert 'ERR_GetDriverErrorString' in client.error_strings(csr)
    with pytest.raises(DeviceNack):
        client.move_absolute(1, 0.0, 10.0, 100.0)
    client.reset_faults(1)
    active = {a.flag.name for a in CMER.decode(client.request('ERR_CaptureMotorErrorRegister', 1))}
    assert 'fault' not in active
    client.move_absolute(1, 0.0, 30.0, 100.0)
    settle(client, 1, 0.0)


def test_injected_nack_surfaces_with_advice(client, sim):
    sim.model.nack_next(0x16, COMMANDS['MOT_GetLoadPosition'].opcode)
    with pytest.raises(DeviceNack, match=r'Pedestal unavailable.*power cycle'):
        client.read_axis(1)
    assert client.read_axis(1)[0] == 0.0  # the next request works


def test_wrong_checksum_nack_is_retried(client, sim):
    sim.model.nack_next(0xF6, COMMANDS['MOT_GetLoadPosition'].opcode)
    assert client.request('MOT_GetLoadPosition', 1) == 0.0


def test_garbage_before_a_reply_is_skipped(client, sim):
    sim.inject_garbage(b'\x00\x50\x13\x50\x54\x08\x00garbage')
    for _ in range(5):
        assert client.request('MOT_GetLoadPosition', 1) == 0.0
    assert client.garbage_bytes > 0


def test_lost_reply_times_out_then_recovers(client, sim):
    client.timeout = LOST_TIMEOUT
    sim.model.lose_replies(1)
    with pytest.raises(DeviceTimeout):
        client.request('MOT_Update', 1)  # setters are not retried
    # the getter's first reply is lost and its retry answered: the retry gets the time a pty
    # answer can take here (with 0.3 s, a crowded run timed the retry out too, the third
    # timeout in a row, and the link closed as silent)
    client.timeout = REQUEST_TIMEOUT
    sim.model.lose_replies(1)
    assert client.request('MOT_GetLoadPosition', 1) == 0.0  # getters retry once
    assert client.connected


def test_bad_arguments_are_refused_before_sending(client, sim):
    before = len(sim.model.requests)
    with pytest.raises(ProtocolError):
        client.request('MOT_SendPosition', 1, math.nan)
    with pytest.raises(ProtocolError):
        client.request('MOT_GetLoadPosition', 7)
    assert len(sim.model.requests) == before


def test_scan_runs_on_the_device_and_stops(client, sim):
    client.configure_scan(-10.0, 10.0, 0.0, 2, 5.0, 40.0)
    client.start_scan('snake')
    assert client.request('SCN_IsScanOn') is True
    assert client.request('COM_SysState') & (1 << 2)
    seen = set()
    wait_for(lambda: seen.add(round(client.read_axis(2)[0])) or {0, 5, 10} <= seen, 15.0,
             'scan rows')
    with pytest.raises(DeviceNack):  # motor writes are refused while scanning (4.3)
        client.request('MOT_SetSpeed', 1, 5.0)
    client.request('SCN_StopScan')
    assert client.request('SCN_IsScanOn') is False


def test_presets_and_looping(client, sim):
    client.set_preset(1, 'left', [15.0, 5.0])
    client.set_preset(2, 'right', [-15.0, -5.0])
    assert client.preset_indices() == [1, 2]
    assert client.get_preset(1).name == 'left'
    client.request('PRST_GoToPreset', 1)
    settle(client, 1, 15.0)
    client.request('PRST_SetLoopingDelay', None, 80.0)
    client.request('PRST_StartPresetLooping')
    wait_for(lambda: client.read_axis(1)[0] < -14.0, 15.0, 'loop reached preset 2')
    client.request('PRST_StopPresetLooping')
    client.request('PRST_ClearSinglePreset', 2)
    assert client.preset_indices() == [1]


def test_gps_imu_and_goto_target(client, sim):
    ready, latitude, longitude = client.gps_fix()
    assert ready and latitude == pytest.approx(32.1040) and longitude == pytest.approx(34.8915)
    target = GeoPoint(34.8921, 32.1050, 64.97)
    client.goto_lla(3, target)
    pan, _tilt = aim_at(sim.model.gps_position, 0.0, target)
    settle(client, 1, pan, tolerance=1e-3, timeout=15.0)
    imu = client.imu()
    assert imu['pitch'] == pytest.approx(client.read_axis(2)[0], abs=1e-3)


def test_threads_share_one_client(client):
    errors = []

    def worker(axis):
        try:
            for _ in range(30):
                client.read_axis(axis)
        except Exception as exc:  # noqa: BLE001
            errors.append(exc)

    threads = [threading.Thread(target=worker, args=(a,)) for a in (1, 2, 1, 2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors


def test_tcp_link_drop_raises_not_connected_until_reopened(sim):
    """The client has no reconnect loop of its own: a lost link raises NotConnected and
    stays closed until connect() (the controller's supervisor, test_device.py) reopens it."""
    c = tcp_client(sim, keepalive_period=0.2)
    c.connect()
    c.start()
    try:
        sim.drop_link()
        with pytest.raises(NotConnected):
            for _ in range(50):
                c.read_axis(1)
        assert not c.connected
        c.connect()
        assert c.connected
        assert c.read_axis(1)[0] == 0.0
        assert c.connects >= 2
    finally:
        c.stop()


def test_pty_link_drop_raises_not_connected_until_reopened(sim):
    c = pty_client(sim)
    c.connect()
    try:
        sim.pty.drop_link(offline_for=0.2)
        with pytest.raises(NotConnected):
            for _ in range(50):
                c.read_axis(1)
        wait_for(lambda: _reopens(c), 10.0, 'reopened after the pty came back')
        assert c.read_axis(2)[0] == 0.0
    finally:
        c.stop()


def _reopens(c: CaptureClient) -> bool:
    try:
        c.connect()
    except NotConnected:
        return False
    return c.connected


def test_silent_device_closes_the_link(sim):
    c = tcp_client(sim, max_timeouts=2)
    c.connect()
    c.timeout = 0.1  # short where nothing is to come: the answers before and after get theirs
    sim.set_silent(True)
    # a getter and its retry unanswered: max_timeouts request timeouts of silence. A retry
    # held past its write bound on a loaded machine raises DeviceTimeout ('the link stayed
    # busy') without counting, so the link must close within a few requests, not the first
    with pytest.raises(NotConnected, match='device silent'):
        for _ in range(5):
            with contextlib.suppress(DeviceTimeout):
                c.request('MOT_GetLoadPosition', 1)
    assert not c.connected
    sim.set_silent(False)
    c.timeout = REQUEST_TIMEOUT
    c.connect()
    assert c.read_axis(1)[0] == 0.0
    c.close()


def test_a_lost_keepalive_answer_is_asked_again_without_a_back_off(sim):
    """The idle link's ping is the controller's supervision: one lost answer must not hold
    the next ping for the optional polls' back-off (1 s), past the 3 x 0.3 s the controller
    allows before it powers the axes off."""
    c = tcp_client(sim, keepalive_period=0.3)
    c.connect()
    c.timeout = 0.1  # the lost answer's wait (a ping answered late counts as lost: the same)
    c.start()
    ping = COMMANDS['COM_IsKeepAliveOn'].opcode

    def pings() -> int:
        return sim.model.request_counts[ping]

    try:
        wait_for(lambda: pings() >= 1, 10.0, 'a keep-alive ping')
        sim.model.lose_replies(1)
        lost = pings()
        wait_for(lambda: pings() >= lost + 3, 10.0, 'pings after the lost answer')
        assert sim.model.keepalive_on and sim.model.axes[1].axis_on
    finally:
        c.stop()


def test_keepalive_keeps_the_axes_on_and_expiry_stops_them(sim):
    c = tcp_client(sim, keepalive_period=0.2)
    c.connect()
    c.start()
    assert c.request('COM_IsKeepAliveOn') is True
    c.jog(1, 10.0, 200.0)
    threading.Event().wait(1.0)  # idle: only the keep-alive thread talks
    assert sim.model.axes[1].axis_on
    c._stop.set()  # the host "dies": no more keep-alives
    wait_for(lambda: not sim.model.axes[1].axis_on, 10.0, 'controller stopped the axes')
    assert sim.model.axes[1].velocity == 0.0
    c.stop()


def test_capture_sim_process_with_control_console():
    import json
    import socket
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, '-m', 'capture_driver.sim', '--port', '0', '--pty',
         '--control-port', '0', '--time-scale', '4'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    try:
        info = read_ready_line(proc.stdout, 'capture_sim')
        c = CaptureClient(lambda: TcpStream('127.0.0.1', info['port']))
        c.connect()
        with socket.create_connection(('127.0.0.1', info['control_port'])) as control:
            stream = control.makefile('rw')
            stream.write('nack MOT_Update 1 A6\n')
            stream.flush()
            assert stream.readline().strip() == 'ok'
            with pytest.raises(DeviceNack):
                c.request('MOT_Update', 1)
            stream.write('state\n')
            stream.flush()
            state = json.loads(stream.readline().split(' ', 1)[1])
            assert state['axes']['1']['axis_on'] is True
            stream.write('bogus\n')
            stream.flush()
            assert stream.readline().startswith('error')

            def ask(line: str) -> str:
                stream.write(line + '\n')
                stream.flush()
                return stream.readline().strip()

            # the shared fault verbs act on the TCP link the client uses
            assert ask('fault over_current 2') == 'ok'
            assert c.request('MOT_MerRegister', 2) & (1 << 8)
            assert ask('nack on') == 'ok'
            with pytest.raises(DeviceNack):
                c.request('MOT_GetLoadPosition', 1)
            assert ask('clear') == 'ok'
            assert c.request('MOT_MerRegister', 2) == 0
            assert ask('garbage hex 13 37') == 'ok 2 bytes'
            wait_for(lambda: c.request('COM_IsConnected') and c.garbage_bytes >= 2, 10,
                     'the garbage to be skipped')
            assert ask('silence on') == 'ok'
            with pytest.raises(DeviceTimeout):
                c.request('MOT_GetLoadPosition', 1)
            assert ask('silence off') == 'ok'
            assert ask('drop 0') == 'ok'
            with pytest.raises((NotConnected, DeviceTimeout, OSError)):
                for _ in range(20):
                    c.request('MOT_GetLoadPosition', 1)
        c.close()
    finally:
        proc.terminate()
        proc.wait(10)


def test_truncated_packet_before_a_reply_is_resynchronised(client, sim):
    # A packet that lost its tail (length says 8, only 3 bytes follow the header). Its
    # bytes plus the start of the real reply must not sum to a valid checksum by chance
    # (an 8-bit checksum collides 1 time in 256; 0x41 here would).
    sim.inject_garbage(bytes.fromhex('50 54 08 00 01 01 09 42'))
    for _ in range(3):
        assert client.request('MOT_GetLoadPosition', 1) == 0.0
    assert client.connected


def test_rangefinder_commands(client):
    assert client.request('LRF_IsConnected') is True
    client.request('LRF_SetManualDistance', None, 120.0)
    client.request('LRF_SetDistanceSource', None, 0)
    assert client.request('LRF_GetTargetDistance') == 120.0
    client.request('LRF_StartMeasurement')
    client.request('LRF_SetDistanceSource', None, 1)
    assert client.request('LRF_GetTargetDistance') == 850.0
    assert client.request('LRF_GetLRFDistance', 2) == 860.0
    with pytest.raises(ProtocolError):
        client.request('LRF_GetLRFDistance', 6)
    client.request('LRF_StopMeasurement')


def test_three_axis_pedestal():
    with CaptureSimulator(PedestalModel(axes=3, time_scale=8.0), tcp_port=0) as sim3:
        c = tcp_client(sim3)
        c.connect()
        c.move_absolute(3, -12.0, 60.0, 300.0)
        settle(c, 3, -12.0)
        assert c.request('IMU_GetRoll') == pytest.approx(-12.0)
        assert c.registers(3)['CMER'] & (1 << 1)  # axis on
        c.close()
    two_axis = PedestalModel(axes=2)
    assert 3 not in two_axis.axes


def _sent(sim, name: str) -> int:
    opcode = COMMANDS[name].opcode
    return sim.model.request_counts[opcode]


def test_identity_uses_the_witnessed_opcodes(client, sim):
    ident = client.identity()
    assert (ident.part_number, ident.serial_number, ident.hardware, ident.firmware) == (
        'CAP-PT2-SIM', '24017', '3.1', '2.24.0')
    assert not client.unsupported
    for name, opcode in (('COM_GetPn', 0x0C2D), ('COM_GetSn', 0x0C2F), ('COM_GetHw', 0x0C4C)):
        assert _sent(sim, name) == 1 and COMMANDS[name].opcode == opcode


def test_poll_of_an_opcode_the_device_does_not_know_stops():
    """A device without GPS_GetLatitude: one 0xA6, recorded with the device's reason, the
    protocol-error flag it raised is cleared, and the fix poll never sends it again."""
    model = PedestalModel(time_scale=8.0, unknown_commands=['GPS_GetLatitude'])
    with CaptureSimulator(model, tcp_port=0) as sim:
        c = tcp_client(sim)
        c.connect()
        assert c.gps_fix() is None
        assert c.unsupported == {'GPS_GetLatitude': '0x0505 answered NACK 0xA6 '
                                                    '"Opcode not Recognized"'}
        assert c.request('ERR_CaptureSystemRegister') == 0  # the flag it raised is cleared
        before = len(sim.model.requests)
        for _ in range(3):
            assert c.gps_fix() is None
        assert len(sim.model.requests) == before  # nothing at all is sent for the fix
        assert _sent(sim, 'GPS_GetLatitude') == 1
        c.close()


def test_protocol_error_flag_is_kept_when_other_errors_are_set():
    model = PedestalModel(time_scale=8.0, unknown_commands=['COM_GetSn'])
    with CaptureSimulator(model, tcp_port=0) as sim:
        sim.model.inject_system_fault('gps_position_error')
        c = tcp_client(sim)
        c.connect()
        assert c.identity().serial_number == ''
        assert 'COM_GetSn' in c.unsupported
        assert c.request('ERR_CaptureSystemRegister') & (1 << 7)  # not ours alone to clear
        c.close()


def test_reset_faults_on_a_device_without_the_opcode_reports_its_answer():
    model = PedestalModel(time_scale=8.0, unknown_commands=['MOT_ResetFaults'])
    with CaptureSimulator(model, tcp_port=0) as sim:
        c = tcp_client(sim)
        c.connect()
        sim.model.inject_fault(1, 'over_current')
        with pytest.raises(DeviceNack, match=r'MOT_ResetFaults \(axis 1\): NACK 0xA6.*'
                                             r'device says: Opcode not Recognized'):
            c.reset_faults(1)
        assert sim.model.axes[1].faulted
        c.close()


def test_video_tracker_pelco_relay_and_dual_gimbal_commands(client, sim):
    # camera index in the group byte: each camera keeps its own mode and detections
    sim.model.detected_targets[2] = [(120, 80), (16, 9)]
    client.request('VDT_setTrackingOn', 2, 1)
    assert sim.model.requests[-1].group == 2 and sim.model.requests[-1].axis == 0
    assert client.request('VDT_isTrackingOn', 2) is True
    assert client.request('VDT_isAutoModeOn', 2) is False
    assert client.request('VDT_GetTargetsList', 2) == ((120, 80), (16, 9)) + ((0, 0),) * 3
    client.request('VDT_setTrackingOn', 1, 2)  # automatic: waits for a detection
    assert client.request('VDT_isAutoModeOn', 1) is True
    assert client.request('VDT_isTrackingOn', 1) is False
    assert client.request('VDT_isTargetDetected', 1) is False
    with pytest.raises(DeviceNack, match='0xA6'):
        client.request('VDT_setTrackingOn', 0, 3)
    client.request('PELCOD_SetMaxSpd', 2, 45.0)
    assert client.request('PELCOD_GetMaxSpd', 2) == 45.0
    assert client.request('PELCOD_GetMaxSpd', 1) == 0.0
    client.request('RLY_ActivateModule', None, 1)
    client.request('STB_SetPosKi', 1, 0.25)
    assert client.request('STB_GetPosKi', 1) == 0.25
    client.request('DG_SetMaxDiff', 2, 0.01)
    assert client.request('DG_GetMaxDiff', 2) == pytest.approx(0.01)


SETUP_COMMANDS = ('MOT_SetPositionMode', 'MOT_SetTum', 'MOT_SetPositionAbsolute',
                  'MOT_SetAcceleration', 'MOT_SetSpeed', 'MOT_SendPosition', 'MOT_Update',
                  'MOT_SetSpeedMode')


def _sent_since(sim, before: dict[str, int]) -> dict[str, int]:
    return {name: _sent(sim, name) - before[name] for name in SETUP_COMMANDS
            if _sent(sim, name) > before[name]}


def _counts(sim) -> dict[str, int]:
    return {name: _sent(sim, name) for name in SETUP_COMMANDS}


def test_repeated_absolute_moves_send_only_what_changed(client, sim):
    client.move_absolute(1, 10.0, 60.0, 200.0)
    settle(client, 1, 10.0)
    before = _counts(sim)
    client.move_absolute(1, -5.0, 40.0, 200.0)  # same mode and acceleration, new speed
    assert _sent_since(sim, before) == {'MOT_SetTum': 1, 'MOT_SetSpeed': 1,
                                        'MOT_SendPosition': 1, 'MOT_Update': 1}
    settle(client, 1, -5.0)
    before = _counts(sim)
    client.move_absolute(1, 3.0, 40.0, 300.0)  # a new acceleration is sent, the speed is not
    assert _sent_since(sim, before) == {'MOT_SetTum': 1, 'MOT_SetAcceleration': 1,
                                        'MOT_SendPosition': 1, 'MOT_Update': 1}
    settle(client, 1, 3.0)
    before = _counts(sim)
    client.move_absolute(1, 7.0, 40.0, 300.0)  # a stream at one speed: TUM, position, update
    assert _sent_since(sim, before) == {'MOT_SetTum': 1, 'MOT_SendPosition': 1,
                                        'MOT_Update': 1}
    settle(client, 1, 7.0)
    assert sim.model.axes[1].speed == 40.0  # the speed register kept the last value


def test_anything_else_commanded_brings_back_the_full_setup(client, sim):
    # the whole 7.1 set-up, then the TUM armed for the next move
    full = {**dict.fromkeys(('MOT_SetPositionMode', 'MOT_SetPositionAbsolute',
                             'MOT_SetAcceleration', 'MOT_SetSpeed', 'MOT_SendPosition',
                             'MOT_Update'), 1), 'MOT_SetTum': 2}
    client.move_absolute(2, 5.0, 60.0, 200.0)
    settle(client, 2, 5.0)
    client.request('STB_StabilizationOff')  # any other setter: the mode may have changed
    before = _counts(sim)
    client.move_absolute(2, 8.0, 60.0, 200.0)
    assert _sent_since(sim, before) == full
    settle(client, 2, 8.0)
    client.stop_axis(2)  # a stop leaves speed mode: the next move sets position mode again
    before = _counts(sim)
    client.move_absolute(2, 2.0, 60.0, 200.0)
    assert _sent_since(sim, before) == full
    settle(client, 2, 2.0)
    client.close()
    client.connect()  # a new connection knows nothing
    before = _counts(sim)
    client.move_absolute(2, 0.0, 60.0, 200.0)
    assert _sent_since(sim, before) == full
    settle(client, 2, 0.0)


def test_every_update_of_a_move_stream_has_its_own_tum_sent_after_the_previous_one(
        client, sim):
    """4.2.14: TUM before each command session. In a stream it is sent right after the
    previous MOT_Update (armed for the next session), so the device acts one round trip
    sooner; a poll between them changes nothing."""
    start = len(sim.model.requests)
    for i in range(6):
        client.move_absolute(1, 2.0 + i, 60.0, 200.0)
        client.read_many(POLL)  # the poll between two commands
    sent = [(BY_OPCODE[f.opcode].name, f.axis) for f in list(sim.model.requests)[start:]]
    names = [name for name, axis in sent if axis == 1 and name in SETUP_COMMANDS]
    updates = [i for i, name in enumerate(names) if name == 'MOT_Update']
    assert len(updates) == 6
    previous = -1
    for index in updates:  # exactly one TUM since the previous MOT_Update
        assert names[previous + 1:index].count('MOT_SetTum') == 1, names
        previous = index
    # from the second move on: position and update, then at once the next session's TUM
    # (before the poll), also after the last move
    assert names[updates[1] - 1:updates[1] + 2] == ['MOT_SendPosition', 'MOT_Update',
                                                    'MOT_SetTum']
    after_update = [sent[i + 1] for i, request in enumerate(sent)
                    if request == ('MOT_Update', 1)]
    assert after_update == [('MOT_SetTum', 1)] * 6
    settle(client, 1, 7.0)


def test_a_failed_tum_for_the_next_move_is_sent_by_that_move(client, sim):
    client.move_absolute(1, 3.0, 60.0, 200.0)
    sim.model.nack_next(0x16, COMMANDS['MOT_SetTum'].opcode)  # refuses the armed TUM
    client.move_absolute(1, 4.0, 60.0, 200.0)  # the move itself worked
    before = _counts(sim)
    client.move_absolute(1, 5.0, 60.0, 200.0)
    assert _sent_since(sim, before) == {'MOT_SetTum': 2, 'MOT_SendPosition': 1,
                                        'MOT_Update': 1}
    settle(client, 1, 5.0)


def test_a_jog_stream_sends_speed_and_update_only(client, sim):
    client.jog(1, 10.0, 300.0)
    wait_for(lambda: client.read_axis(1)[1] > 5.0, 5.0, 'jogging +')
    before = _counts(sim)
    client.jog(1, -20.0, 300.0)
    assert _sent_since(sim, before) == {'MOT_SetSpeed': 1, 'MOT_Update': 1}
    wait_for(lambda: client.read_axis(1)[1] < -15.0, 5.0, 'jogging - at the new speed')
    before = _counts(sim)
    client.stop_axis(1)  # a stop always sends its whole sequence
    assert _sent_since(sim, before) == {'MOT_SetSpeedMode': 1, 'MOT_SetSpeed': 1,
                                        'MOT_Update': 1}
    wait_for(lambda: client.read_axis(1)[1] == 0.0, 5.0, 'stopped')


POLL = [(name, axis) for axis in (1, 2) for name in ('MOT_GetLoadPosition', 'MOT_GetMotorSpeed')]


class CountingWrites:
    """Wraps a client's stream factory: counts the writes the client makes."""

    def __init__(self, factory) -> None:
        self.factory = factory
        self.writes = 0

    def __call__(self):
        stream = self.factory()
        write = stream.write

        def counted(data: bytes) -> None:
            self.writes += 1
            write(data)

        stream.write = counted
        return stream


def batched_client(sim, transport: str, **kwargs) -> tuple[CaptureClient, CountingWrites]:
    kwargs.setdefault('timeout', REQUEST_TIMEOUT)
    if transport == 'tcp':
        writes = CountingWrites(lambda: TcpStream('127.0.0.1', sim.tcp.port))
        c = CaptureClient(writes, **kwargs)
    else:
        writes = CountingWrites(lambda: SerialStream(sim.pty.port_name))
        c = CaptureClient(writes, expect_greeting=False, **kwargs)
    c.connect()
    return c, writes


@pytest.mark.parametrize('transport', ['tcp', 'pty'])
def test_batched_poll_is_one_write_with_the_same_values(sim, transport):
    c, writes = batched_client(sim, transport)
    try:
        c.move_absolute(1, 12.0, 60.0, 200.0)
        c.move_absolute(2, -7.5, 60.0, 200.0)
        settle(c, 1, 12.0)
        settle(c, 2, -7.5)
        before = writes.writes
        values = c.read_many(POLL)
        assert writes.writes == before + 1  # four getters, one write
        assert values == [c.request(name, axis) for name, axis in POLL]
        assert values[0] == pytest.approx(12.0) and values[2] == pytest.approx(-7.5)
        before = writes.writes
        registers = c.registers(1)
        assert writes.writes == before + 1
        assert registers == {register.name: c.request(register.command, 1)
                             for register in REGISTERS.values() if register.per_axis}
        assert c.batching and c.stats['timeouts'] == c.stats['incomplete_batches'] == 0
    finally:
        c.stop()


def test_a_nacked_read_in_a_batch_is_sent_again_alone(sim):
    c, _ = batched_client(sim, 'tcp')
    try:
        sim.model.nack_next(0xF6, COMMANDS['MOT_GetMotorSpeed'].opcode)  # checksum: resend
        assert c.read_many(POLL) == [0.0] * 4
        assert c.stats['nacks'] == 1 and c.batching
        sim.model.nack_next(0x16, COMMANDS['MOT_GetLoadPosition'].opcode)
        assert c.read_many(POLL) == [0.0] * 4  # refused once in the batch, then answered
        sim.model.nack_all = ReplyCode(0x16)  # refused every time: the poll fails with it
        with pytest.raises(DeviceNack, match='Pedestal unavailable'):
            c.read_many(POLL)
        sim.model.nack_all = None
        assert c.read_many(POLL) == [0.0] * 4  # and the next poll is whole again
    finally:
        c.stop()


def test_a_lost_reply_in_a_batch_is_read_again_alone(sim):
    c, writes = batched_client(sim, 'tcp', timeout=LOST_TIMEOUT)
    try:
        sim.model.lose_replies(1)
        assert c.read_many(POLL) == [0.0] * 4
        assert c.batching and c.connected and c.stats['incomplete_batches'] == 1
        before = writes.writes
        assert c.read_many(POLL) == [0.0] * 4
        assert writes.writes == before + 1  # one bad batch does not end batching
    finally:
        c.stop()


@pytest.mark.parametrize('transport', ['tcp', 'pty'])
def test_a_controller_that_drops_queued_requests_is_read_one_at_a_time(sim, transport):
    sim.model.one_request_per_read = True
    c, writes = batched_client(sim, transport, timeout=LOST_TIMEOUT)
    try:
        c.move_absolute(1, 4.0, 60.0, 200.0)
        settle(c, 1, 4.0)
        for _ in range(3):  # every batch comes back with one reply: the rest read alone
            assert c.read_many(POLL)[0] == pytest.approx(4.0)
        assert not c.batching
        before = writes.writes
        assert c.read_many(POLL)[0] == pytest.approx(4.0)
        assert writes.writes == before + 4
        assert c.connected and c.stats['incomplete_batches'] == 3
        c.connect()  # a new connection tries batches again
        assert c.batching
    finally:
        c.stop()


def test_batched_reads_off_reads_one_at_a_time(sim):
    c, writes = batched_client(sim, 'tcp', batch_reads=False)
    try:
        before = writes.writes
        assert c.read_many(POLL) == [0.0] * 4
        assert writes.writes == before + 4 and not c.batching
        with pytest.raises(ProtocolError, match='not a getter'):
            c.read_many([('MOT_Update', 1), ('MOT_GetLoadPosition', 1)])
    finally:
        c.stop()


def late_returning_writes(factory, seconds: float):
    """``factory``'s streams, each write returning ``seconds`` after its bytes went out:
    a writer thread that waited for a core (a pinned run) after its request was written.
    The sleep is the fault injected, not a wait for a condition; 0 s: ``factory`` as is."""
    if not seconds:
        return factory

    def make():
        stream = factory()
        write = stream.write

        def late(data: bytes) -> None:
            write(data)
            time.sleep(seconds)

        stream.write = late
        return stream
    return make


# With late-returning writes: the time a write call takes after its request went out is
# part of that request's wait (its deadline runs from then), the device's silence, not the
# link's resynchronisation. It once was not, and the link stayed open after three timeouts
# on one core (docs/testing.md, the whole pinned run of 2026-12-03).
@pytest.mark.parametrize('write_return_s', [0.0, 0.03], ids=['writes', 'late-writes'])
def test_silent_device_during_batched_reads_closes_the_link(sim, write_return_s):
    streams = late_returning_writes(lambda: TcpStream('127.0.0.1', sim.tcp.port),
                                    write_return_s)
    c = CaptureClient(streams, timeout=REQUEST_TIMEOUT, max_timeouts=3)
    c.connect()
    c.timeout = 0.1
    sim.set_silent(True)
    # the silent batch counts once, then the first read alone and its retry: link closed
    with pytest.raises(NotConnected, match='device silent'):
        c.read_many(POLL)
    assert not c.connected and c.stats['timeouts'] == 3
    sim.set_silent(False)
    c.timeout = REQUEST_TIMEOUT
    c.connect()
    assert c.read_many(POLL) == [0.0] * 4
    c.close()


# ------------------------------------------------------- stream moves (post_moves)
# Written without waiting for their ACKs: what goes out, who reads the ACKs, and what
# happens when they are refused, lost, or overtaken by a stop.

SPEED, ACCELERATION = 60.0, 200.0


@pytest.fixture
def link(sim):
    """``link(transport='tcp')``: a connected batching client and its write counter;
    every client made is stopped after the test."""
    made = []

    def connect(transport: str = 'tcp', **kwargs: Any) -> tuple[CaptureClient, CountingWrites]:
        made.append(batched_client(sim, transport, **kwargs))
        return made[-1]

    yield connect
    for client, _ in made:
        client.stop()


def requests_since(sim, start: int) -> list[tuple[str, int]]:
    """(command, axis) of every request the simulator got since ``start``."""
    return [(BY_OPCODE[f.opcode].name, f.axis) for f in list(sim.model.requests)[start:]]


@pytest.mark.parametrize('transport', ['tcp', 'pty'])
def test_a_stream_move_goes_out_in_one_write_once_the_axis_is_set_up(sim, link, transport):
    client, writes = link(transport)
    before = writes.writes
    assert client.post_moves({1: (5.0, SPEED, ACCELERATION)}) is None  # not set up yet
    assert writes.writes == before
    client.move_absolute(1, 5.0, SPEED, ACCELERATION)  # the set-up, and a TUM armed
    settle(client, 1, 5.0)
    start, before = len(sim.model.requests), writes.writes
    posted = client.post_moves({1: (9.0, SPEED, ACCELERATION)})
    assert posted is not None and writes.writes == before + 1
    assert [w.name for w in posted.waitings] == ['MOT_SendPosition', 'MOT_Update']
    assert client.settle_posted(posted)  # reads both ACKs, arms the next session's TUM
    assert requests_since(sim, start) == [('MOT_SendPosition', 1), ('MOT_Update', 1),
                                          ('MOT_SetTum', 1)]
    settle(client, 1, 9.0)
    # another speed needs MOT_SetSpeed: not a stream move, sent by move_absolute
    assert client.post_moves({1: (3.0, SPEED / 2, ACCELERATION)}) is None
    assert client.settle_posted(client.post_moves({1: (3.0, SPEED, ACCELERATION)}))
    settle(client, 1, 3.0)
    assert client.stats['nacks'] == client.stats['timeouts'] == client.stats['stale'] == 0


def test_the_poll_reads_beside_a_post_and_the_next_setter_settles_it_first(sim):
    """Setters hold the link lock they were given; the lock's ``before_use`` (the core's
    command path in a node) takes a posted move's ACKs before the next setter writes. The
    poll's getters hold no lock: they go out beside the post, and the reader gives each
    answer to its own request (data packets by opcode and axis, the ACKs to the post)."""
    lock, posts, settled = LinkLock(), [], []
    client = CaptureClient(lambda: TcpStream('127.0.0.1', sim.tcp.port), timeout=0.3,
                           link_lock=lock)

    def settle_posted() -> None:  # what the command path's settle does, in short
        while posts:
            settled.append(client.settle_posted(posts.pop()))

    lock.before_use = settle_posted
    client.connect()
    try:
        # once answered with data, the poll's getters are data-answered: they go out beside
        # the post (a getter not known yet would wait for it, see answers.py)
        client.read_many(POLL)
        client.move_absolute(1, 1.0, SPEED, ACCELERATION)
        client.move_absolute(2, -1.0, SPEED, ACCELERATION)
        assert lock.try_hold()  # as the joint_command callback does: no settle
        try:
            posts.append(client.post_moves({1: (4.0, SPEED, ACCELERATION),
                                            2: (-4.0, SPEED, ACCELERATION)}))
        finally:
            lock.release()
        assert posts[0] is not None and settled == []
        assert len(client.read_many(POLL)) == 4  # beside the post: nothing settled
        assert settled == [] and client.stats['stale'] == 0
        client.request('COM_setKeepAliveCount', None, 3)  # a setter: the lock settles first
        assert settled == [True] and client.stats['stale'] == 0
        settle(client, 1, 4.0)
        settle(client, 2, -4.0)
    finally:
        client.stop()


def test_a_refused_stream_move_is_reported_and_the_next_move_sets_up_again(sim, link):
    client, _ = link()
    client.move_absolute(1, 2.0, SPEED, ACCELERATION)
    sim.model.nack_next(0x16, COMMANDS['MOT_SendPosition'].opcode)
    posted = client.post_moves({1: (6.0, SPEED, ACCELERATION)})
    with pytest.raises(DeviceNack, match=r'MOT_SendPosition \(axis 1\).*0x16'):
        client.settle_posted(posted)
    settle(client, 1, 2.0)  # the MOT_Update after it re-ran the previous profile
    assert client.post_moves({1: (6.0, SPEED, ACCELERATION)}) is None  # set-up forgotten
    start = len(sim.model.requests)
    client.move_absolute(1, 6.0, SPEED, ACCELERATION)
    assert ('MOT_SetPositionMode', 1) in requests_since(sim, start)
    settle(client, 1, 6.0)


def test_a_stream_move_with_a_lost_ack_is_sent_again_one_request_at_a_time(sim, link):
    client, _ = link(timeout=LOST_TIMEOUT)
    client.move_absolute(1, 2.0, SPEED, ACCELERATION)
    sim.model.lose_replies(1)
    posted = client.post_moves({1: (7.0, SPEED, ACCELERATION)})
    start = len(sim.model.requests)
    # one ACK of two: which one is lost, the byte does not say; the caller sends it again
    assert not client.settle_posted(posted)
    client.move_absolute(1, 7.0, SPEED, ACCELERATION)
    assert ('MOT_SetPositionMode', 1) in requests_since(sim, start)  # the whole 7.1 set-up
    assert client.stats['incomplete_batches'] == 1 and client.connected
    settle(client, 1, 7.0)


@pytest.mark.parametrize('transport', ['tcp', 'pty'])
def test_a_controller_that_drops_queued_requests_gets_moves_one_at_a_time(sim, link, transport):
    sim.model.one_request_per_read = True
    # answered requests get REQUEST_TIMEOUT: with LOST_TIMEOUT for all of them, an answered
    # MOT_SetPositionMode timed out in a loaded make test run (the simulator shares this
    # process); only the post, whose MOT_Update is lost on purpose, waits LOST_TIMEOUT
    client, _ = link(transport, timeout=REQUEST_TIMEOUT)
    target = 1.0
    client.move_absolute(1, target, SPEED, ACCELERATION)
    for _ in range(3):  # each post loses its MOT_Update: sent again, and counted
        target += 1.0
        client.timeout = LOST_TIMEOUT
        assert not client.settle_posted(client.post_moves({1: (target, SPEED, ACCELERATION)}))
        client.timeout = REQUEST_TIMEOUT
        client.move_absolute(1, target, SPEED, ACCELERATION)
        settle(client, 1, target)
    assert not client.batching
    assert client.post_moves({1: (target + 1.0, SPEED, ACCELERATION)}) is None


def test_a_link_lost_before_the_acks_is_reported_as_not_connected(sim, link):
    client, _ = link()
    client.move_absolute(1, 1.0, SPEED, ACCELERATION)
    posted = client.post_moves({1: (3.0, SPEED, ACCELERATION)})
    client.close()
    with pytest.raises(NotConnected, match='stream move'):
        client.settle_posted(posted)
    client.connect()
    with pytest.raises(NotConnected, match='stream move'):  # not the new connection's
        client.settle_posted(posted)
    assert client.post_moves({1: (3.0, SPEED, ACCELERATION)}) is None  # a new connection


STOP_STEPS = ('MOT_SetSpeedMode', 'MOT_SetSpeed', 'MOT_Update')


def received(sim, since: int) -> list[tuple[str, int]]:
    """(name, axis) of what the simulator received after its first ``since`` requests."""
    return [(BY_OPCODE[f.opcode].name, f.axis) for f in list(sim.model.requests)[since:]
            if f.opcode in BY_OPCODE]


def test_a_stop_with_its_first_step_answered_late_reaches_every_step_of_every_axis(sim):
    """Issue 44 item 1, over TCP: MOT_SetSpeedMode answered 0.7 s late (beyond the request
    timeout) holds up no other step: every step of both axes, then the program stops,
    reach the pedestal in that order (its receive log), and both axes come to rest."""
    c = tcp_client(sim)
    c.connect()
    try:
        c.jog(1, 30.0, 300.0)
        c.jog(2, -20.0, 300.0)
        wait_for(lambda: sim.model.axes[1].velocity > 1.0 and sim.model.axes[2].velocity < -1.0,
                 5.0, 'both axes jogging')
        sim.model.request_faults.delay('MOT_SetSpeedMode', 0.7)
        before = len(sim.model.requests)
        answers = c.stop_axes([1, 2], programs=True)
        log = [item for item in received(sim, before)
               if item[0] in (*STOP_STEPS, 'PRST_StopPresetLooping', 'GPS_StopTargetLooping',
                              'SCN_StopScan')]
        assert log[:9] == [(name, axis) for axis in (1, 2) for name in STOP_STEPS] + [
            ('PRST_StopPresetLooping', 0), ('GPS_StopTargetLooping', 0), ('SCN_StopScan', 0)]
        assert answers.steps == 9
        wait_for(lambda: sim.model.axes[1].velocity == 0.0 and sim.model.axes[2].velocity == 0.0,
                 5.0, 'both axes at rest')
    finally:
        sim.model.request_faults.clear()
        c.stop()


def test_a_scan_stop_answered_after_500_ms_still_stops_the_axes_and_is_no_failure(sim):
    """Issue 44 item 1, over TCP: SCN_StopScan may take 500 ms before its ACK (4.3.9). It
    goes out after the axes' steps, which are answered at once, and its answer 0.55 s
    late is within its own time: the stop reports no problem, and the axes are at rest."""
    c = tcp_client(sim)
    c.connect()
    try:
        c.jog(1, 30.0, 300.0)
        wait_for(lambda: sim.model.axes[1].velocity > 1.0, 5.0, 'the jog')
        sim.model.request_faults.delay('SCN_StopScan', 0.55)
        before = len(sim.model.requests)
        answers = c.stop_axes([1, 2], programs=True)
        assert answers.errors == [] and 'SCN_StopScan' not in answers.programs
        log = received(sim, before)
        assert log.index(('SCN_StopScan', 0)) > log.index(('MOT_Update', 2))
        wait_for(lambda: sim.model.axes[1].velocity == 0.0, 5.0, 'pan at rest')
    finally:
        sim.model.request_faults.clear()
        c.stop()


def test_a_stop_during_a_device_scan_stops_the_axes_and_the_scan(sim):
    """Issue 44, over TCP: while the device scans it refuses motor commands with 0xA6
    (4.3); the stop's axis steps go out first all the same, SCN_StopScan after them ends
    the scan and stops both motors, so those refusals are no failure."""
    c = tcp_client(sim)
    c.connect()
    try:
        c.configure_scan(-10.0, 10.0, 0.0, 2, 5.0, 40.0)
        c.start_scan('snake')
        wait_for(lambda: abs(sim.model.axes[1].velocity) > 1.0, 5.0, 'the scan moving pan')
        before = len(sim.model.requests)
        answers = c.stop_axes([1, 2], programs=True)
        assert answers.errors == [] and answers.programs == {}
        log = received(sim, before)
        assert log.index(('SCN_StopScan', 0)) > log.index(('MOT_Update', 2))
        assert c.request('SCN_IsScanOn') is False
        wait_for(lambda: sim.model.axes[1].velocity == 0.0 and sim.model.axes[2].velocity == 0.0,
                 5.0, 'both axes at rest')
    finally:
        c.stop()
