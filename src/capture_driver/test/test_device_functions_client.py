"""Issue 15 device functions: the client against the simulator over TCP loopback.

Video tracker (camera index in the group byte), axis power, digital I/O, GPS heading and
targets, target looping, IMU levelling and gyro drift. Waits are "up to a timeout".
"""

from __future__ import annotations

import pytest

from capture_driver.client import CaptureClient
from capture_driver.errors import DeviceNack
from capture_driver.protocol import COMMANDS, GeoPoint, ProtocolError, ReplyCode
from capture_driver.sim import GYRO_BIAS, CaptureSimulator, PedestalModel
from gimbal_driver_common.transport import TcpStream
from gimbal_driver_testing import wait_for


@pytest.fixture
def sim():
    simulator = CaptureSimulator(PedestalModel(time_scale=8.0), tcp_port=0).start()
    yield simulator
    simulator.stop()


@pytest.fixture
def client(sim):
    c = CaptureClient(lambda: TcpStream('127.0.0.1', sim.tcp.port), timeout=0.5)
    c.connect()
    yield c
    c.stop()


def test_video_tracker_opcodes_come_from_revision_2_21():
    assert {name: COMMANDS[name].opcode for name in (
        'VDT_setTrackingOn', 'VDT_isTrackingOn', 'VDT_isAutoModeOn', 'VDT_isTargetDetected',
    )} == {'VDT_setTrackingOn': 0x0A01, 'VDT_isTrackingOn': 0x0A02,
           'VDT_isAutoModeOn': 0x0A04, 'VDT_isTargetDetected': 0x0A13}


def test_tracking_request_carries_the_camera_in_the_group_byte(sim, client):
    client.set_tracking(2, 2)
    frame = sim.model.requests[-1]
    assert (frame.group, frame.axis, frame.opcode, frame.data) == (2, 0, 0x0A01, b'\x02')
    assert client.group == 0  # the pedestal's own group is restored
    assert sim.model.tracker_mode == {0: 0, 1: 0, 2: 2, 3: 0}


def test_manual_tracking_needs_a_detected_target_and_stops_when_it_is_lost(sim, client):
    client.set_tracking(0, 1)
    state = client.tracking_state(0)
    assert (state.active, state.mode, state.target_detected) == (False, 'off', False)
    sim.model.set_target_detected(0, True)
    client.set_tracking(0, 1)
    state = client.tracking_state(0)
    assert (state.active, state.mode) == (True, 'manual')
    sim.model.set_target_detected(0, False)
    assert client.tracking_state(0).mode == 'off'


def test_automatic_tracking_waits_for_a_target(sim, client):
    client.set_tracking(1, 2)
    state = client.tracking_state(1)
    assert (state.mode, state.active) == ('auto', False)
    sim.model.set_target_detected(1, True)
    assert client.tracking_state(1).active
    assert client.request('COM_SysState') & (1 << 1)  # system state: tracking


def test_tracker_refusals(sim, client):
    before = len(sim.model.requests)
    with pytest.raises(ProtocolError, match='camera'):  # 0..3, refused before sending
        client.request('VDT_isTrackingOn', 4)
    assert len(sim.model.requests) == before
    sim.model.tracker_present = False
    with pytest.raises(DeviceNack) as exc:
        client.tracking_state(0)
    assert exc.value.code == ReplyCode.VIDEO_TRACKER_UNAVAILABLE


def test_axis_power_off_blocks_motion_and_on_cancels_the_buffered_move(sim, client):
    client.set_axis_power(1, False)
    assert not sim.model.axes[1].axis_on
    with pytest.raises(DeviceNack):
        client.jog(1, 10.0, 100.0)
    client.set_axis_power(1, True)
    assert sim.model.axes[1].axis_on
    assert sim.model.axes[1].target is None and sim.model.axes[1].velocity == 0.0


def test_digital_io_set_and_read(sim, client):
    client.set_digital_output(3, True)
    states = client.digital_io([1, 2, 3, 4, 5, 6])
    assert states == {1: False, 2: False, 3: True, 4: False, 5: False, 6: False}
    frame = sim.model.requests[-1]
    assert (frame.axis, frame.opcode) == (6, 0x0724)  # I/O number in the axis byte
    sim.control('dio 5 1')  # an input changes on the device side
    assert client.digital_io([5]) == {5: True}


def test_gps_heading_and_stored_targets(sim, client):
    sim.model.gps_heading = 30.0
    assert client.gps_heading() == (True, 30.0)
    assert client.stored_targets() == {}
    client.run('GPS_SetTargetLLA', 4, GeoPoint(34.9, 32.11, 60.0))
    targets = client.stored_targets()
    assert list(targets) == [4]
    assert targets[4].latitude == pytest.approx(32.11)


def test_target_looping_visits_the_stored_targets(sim, client):
    with pytest.raises(DeviceNack):
        client.run('GPS_StartTargetLooping')  # no targets
    client.run('GPS_SetTargetLLA', 1, GeoPoint(34.8915, 32.1140, 65.43))  # ~1.1 km north
    client.run('GPS_SetTargetLLA', 2, GeoPoint(34.9015, 32.1040, 65.43))  # ~0.9 km east
    client.run('GPS_StartTargetLooping')
    assert client.request('COM_SysState') & (1 << 4)
    wait_for(lambda: abs(client.read_axis(1)[0] - 90.0) < 1.0, 30.0, 'yaw to the east target')
    client.run('GPS_StopTargetLooping')
    assert not client.request('COM_SysState') & (1 << 4)


def test_imu_leveling_drives_the_axis_to_the_leveling_value(sim, client):
    sim.control('pose 2 12.5')
    client.run('IMU_setLevelingValue', 2, -4.0)
    client.run('IMU_Leveling', 2)
    wait_for(lambda: abs(client.request('IMU_GetPitch') + 4.0) < 1e-3, 20.0, 'pitch levelled')


def test_gyro_drift_compensation_measures_then_resets(sim, client):
    assert client.request('IMU_GetGyroDrift', 2) == 0.0
    client.run('IMU_GyroDriftCompensation', 2)
    wait_for(lambda: client.request('IMU_GetGyroDrift', 2) != 0.0, 20.0, 'drift measured')
    assert client.request('IMU_GetGyroDrift', 2) == pytest.approx(GYRO_BIAS)
    client.run('IMU_ResetGyroDriftCompensation', 2)
    assert client.request('IMU_GetGyroDrift', 2) == 0.0
