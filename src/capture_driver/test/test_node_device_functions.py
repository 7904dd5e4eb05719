"""Issue 15 interfaces of capture_driver_node, as a process against capture_sim as a process.

Rangefinder (~/range, ~/set_ranging), video tracker (~/set_tracking, ~/tracking_state),
digital I/O (~/set_digital_output_<n>, ~/digital_io), levelling and gyro drift (guarded
actions), GPS heading and target looping, and axis enable. One simulator and one node
serve the module; waits are "up to a timeout", never timing assertions.
"""

from __future__ import annotations

import math
import threading

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')
from action_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import Imu, JointState, Range
from std_msgs.msg import UInt8MultiArray
from std_srvs.srv import SetBool, Trigger

from capture_driver.sim import console_state as sim_state
from capture_driver.sim import control
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.ros import joint_positions
from gimbal_msgs.action import Home
from gimbal_msgs.msg import AxisState, GimbalStatus
from gimbal_msgs.srv import DeviceCommand, SetMode, StartScan

pytestmark = pytest.mark.ros

PKG = 'capture_driver'
NODE = 'capture_driver'
PAN_LIMIT = 1.2  # rad: narrower than the default so an eastern GPS target is out of limits


def srv(name: str) -> str:
    return f'/{NODE}/{name}'


@pytest.fixture(scope='module')
def pedestal(capture_rig):
    with capture_rig(
            ['--time-scale', '4'],
            ['publish_rate:=20.0', 'reconnect_period:=0.3', 'diagnostics_period:=0.25',
             'status_period:=0.2', 'default_speed:=1.0', 'acceleration:=6.0',
             f'position_min:=[{-PAN_LIMIT}, {-math.pi / 2}]',
             f'position_max:=[{PAN_LIMIT}, {math.pi / 2}]', 'range_rate:=5.0',
             'range_min:=2.0', 'range_max:=3000.0', 'range_field_of_view:=0.003',
             'tracking_rate:=4.0', 'digital_outputs:=[1, 2]', 'digital_io_rate:=4.0',
             'fix_rate:=4.0', 'gyro_drift_time:=2.0', 'command_timeout:=3.0'],
            node_log_tail=4000) as (started, control_port):
        yield started.ros, control_port


@pytest.fixture
def rig(pedestal):
    """The module's node and simulator, with every drive on and no fault at the start of
    each test: a test that fails half-way (or a keep-alive expiry, which switches the
    drives off) does not fail the tests after it with "drive is off"."""
    ros, control_port = pedestal
    axes = sim_state(control_port)['axes'].values()
    if any(a['faulted'] for a in axes):
        reply = ros.call(Trigger, srv('reset_faults'), Trigger.Request())
        assert reply.success, reply.message
    elif not all(a['axis_on'] for a in axes):
        reply = ros.call(SetBool, srv('enable'), SetBool.Request(data=True))
        assert reply.success, reply.message
    ros.wait_for_message(f'/{NODE}/status', GimbalStatus, lambda m: not set(
        axis_states(m).values()) & {AxisState.STATE_DISABLED, AxisState.STATE_FAULT},
        timeout=15)
    return pedestal


def command(ros, name: str, axis: int = 0, args=()) -> DeviceCommand.Response:
    return ros.call(DeviceCommand, srv('command'), DeviceCommand.Request(
        command=name, axis=axis, arguments=list(args)))


def axis_states(msg: GimbalStatus) -> dict[str, int]:
    return {axis.name: axis.state for axis in msg.axes}


def wait_at_rest(ros, control_port: int) -> None:
    wait_for(lambda: all(a['velocity'] == 0.0 for a in sim_state(control_port)['axes'].values()),
             20.0, 'pedestal at rest')
    ros.wait_for_message('joint_states', JointState, lambda m: all(v == 0.0 for v in m.velocity))


def test_range_published_while_ranging_is_on(rig):
    ros, control_port = rig
    reply = ros.call(SetBool, srv('set_ranging'), SetBool.Request(data=True))
    assert reply.success, reply.message
    assert sim_state(control_port)['lrf_measuring']
    msg = ros.wait_for_message(f'/{NODE}/range', Range, timeout=15)
    assert msg.range == pytest.approx(850.0)  # the simulator's target
    assert (msg.min_range, msg.max_range) == (2.0, 3000.0)
    assert msg.field_of_view == pytest.approx(0.003)
    assert msg.radiation_type == Range.INFRARED
    assert msg.header.frame_id == 'capture_lrf'
    reply = ros.call(SetBool, srv('set_ranging'), SetBool.Request(data=False))
    assert reply.success, reply.message
    assert not sim_state(control_port)['lrf_measuring']
    # no more ranges: while ~/digital_io publishes 8 times (2 s), ~/range stays silent
    ranges = ros.subscribe(f'/{NODE}/range', Range)
    dio = ros.subscribe(f'/{NODE}/digital_io', UInt8MultiArray)
    wait_for(lambda: len(dio) >= 2, 15.0, 'digital_io messages')
    silent_from = len(ranges)
    wait_for(lambda: len(dio) >= 10, 15.0, 'eight more digital_io messages')
    assert len(ranges) == silent_from


def test_set_tracking_modes_and_tracking_state(rig):
    ros, control_port = rig
    bad = ros.call(SetMode, srv('set_tracking'), SetMode.Request(mode='follow'))
    assert not bad.success and "'off', 'manual', 'auto'" in bad.message
    no_target = ros.call(SetMode, srv('set_tracking'), SetMode.Request(mode='manual'))
    assert not no_target.success and 'no target detected' in no_target.message
    assert control(control_port, 'detect 0 on') == 'ok'
    manual = ros.call(SetMode, srv('set_tracking'), SetMode.Request(mode='manual'))
    assert manual.success, manual.message
    state = ros.wait_for_message(
        f'/{NODE}/tracking_state', DiagnosticStatus,
        lambda m: {kv.key: kv.value for kv in m.values}.get('mode') == 'manual', timeout=15)
    values = {kv.key: kv.value for kv in state.values}
    assert values == {'camera': '0', 'mode': 'manual', 'tracking_active': 'true',
                      'target_detected': 'true'}
    auto = ros.call(SetMode, srv('set_tracking'), SetMode.Request(mode='AUTO'))
    assert auto.success, auto.message
    assert sim_state(control_port)['tracker_mode']['0'] == 2
    # ~/command reads the tracker of tracker_camera (group byte) but leaves setting it to
    # ~/set_tracking, whose checks it would skip
    assert command(ros, 'VDT_isAutoModeOn').results == ['True flag']
    refused = command(ros, 'VDT_setTrackingOn', 0, ['0'])
    assert not refused.success and '~/set_tracking' in refused.message
    off = ros.call(SetMode, srv('set_tracking'), SetMode.Request(mode='off'))
    assert off.success, off.message
    assert sim_state(control_port)['tracker_mode']['0'] == 0
    assert control(control_port, 'detect 0 off') == 'ok'


def test_digital_outputs_and_io_topic(rig):
    ros, control_port = rig
    reply = ros.call(SetBool, srv('set_digital_output_2'), SetBool.Request(data=True))
    assert reply.success, reply.message
    assert sim_state(control_port)['digital_io']['2'] == 1
    assert control(control_port, 'dio 6 1') == 'ok'  # an input switches on
    msg = ros.wait_for_message(f'/{NODE}/digital_io', UInt8MultiArray,
                               lambda m: list(m.data) == [0, 1, 0, 0, 0, 1], timeout=15)
    assert msg.layout.dim[0].size == 6
    reply = ros.call(SetBool, srv('set_digital_output_2'), SetBool.Request(data=False))
    assert reply.success, reply.message
    assert sim_state(control_port)['digital_io']['2'] == 0
    # outputs not listed in digital_outputs get no service at all
    names = [name for name, _ in ros.node.get_service_names_and_types()]
    assert srv('set_digital_output_1') in names
    assert srv('set_digital_output_3') not in names


def test_gps_heading_as_enu_yaw(rig):
    ros, _ = rig
    assert command(ros, 'GPS_SetInsertedHeading', 0, ['30']).success
    assert command(ros, 'GPS_SetOvdPosGPS', 0, ['1']).success
    try:
        msg = ros.wait_for_message(
            f'/{NODE}/heading', Imu,
            lambda m: abs(2 * math.atan2(m.orientation.z, m.orientation.w)
                          - math.radians(60.0)) < 1e-4, timeout=15)
    finally:
        assert command(ros, 'GPS_SetOvdPosGPS', 0, ['0']).success
    assert (msg.orientation.x, msg.orientation.y) == (0.0, 0.0)
    assert msg.orientation_covariance[8] > 1.0  # accuracy unknown: large
    assert msg.orientation_covariance[0] > 1.0 and msg.orientation_covariance[4] > 1.0
    assert msg.angular_velocity_covariance[0] == -1.0
    assert msg.linear_acceleration_covariance[0] == -1.0
    assert msg.header.frame_id == 'capture_gps'


def test_target_loop_is_limit_checked_then_runs(rig):
    ros, control_port = rig
    empty = ros.call(Trigger, srv('start_target_loop'), Trigger.Request())
    assert not empty.success and 'no GPS targets' in empty.message
    # ~0.9 km east: pan -pi/2 (Capture yaw is clockwise), beyond pan's 1.2 rad limit
    assert command(ros, 'GPS_SetTargetLLA', 1, ['34.9015 32.1040 65.43']).success
    refused = ros.call(Trigger, srv('start_target_loop'), Trigger.Request())
    assert not refused.success
    assert 'target 1' in refused.message and 'limit' in refused.message
    assert not sim_state(control_port)['target_looping']
    assert command(ros, 'GPS_ClearSingleTarget', 1).success
    assert command(ros, 'GPS_SetTargetLLA', 2, ['34.8915 32.1140 65.43']).success  # north
    assert command(ros, 'GPS_SetTargetLLA', 3, ['34.9015 32.1140 65.43']).success  # ~40 deg
    started = ros.call(Trigger, srv('start_target_loop'), Trigger.Request())
    assert started.success and '[2, 3]' in started.message, started.message
    assert sim_state(control_port)['target_looping']
    stopped = ros.call(Trigger, srv('stop_target_loop'), Trigger.Request())
    assert stopped.success, stopped.message
    assert not sim_state(control_port)['target_looping']
    assert command(ros, 'GPS_ClearAllTargets').success


def test_level_action_drives_tilt_to_the_leveling_value(rig):
    ros, control_port = rig
    wait_at_rest(ros, control_port)
    assert control(control_port, 'pose 2 10') == 'ok'
    assert command(ros, 'IMU_setLevelingValue', 2, ['-3']).success
    result, _, feedback = ros.run_action(Home, srv('level'), Home.Goal(joint_names=['tilt']),
                                         timeout=60)
    assert result.success, result.message
    # feedback travels on its own topic and may arrive after the result
    wait_for(lambda: feedback, 10.0, 'levelling feedback')
    assert 'from level' in feedback[0].state
    assert sim_state(control_port)['axes']['2']['position'] == pytest.approx(-3.0, abs=0.1)
    unknown, _, _ = ros.run_action(Home, srv('level'), Home.Goal(joint_names=['elbow']))
    assert not unknown.success and 'unknown joint' in unknown.message, unknown.message


def test_level_cancel_stops_the_axis(rig):
    ros, control_port = rig
    wait_at_rest(ros, control_port)
    assert control(control_port, 'pose 2 60') == 'ok'
    assert command(ros, 'IMU_setLevelingValue', 2, ['0']).success
    assert command(ros, 'CFG_SetGeneralSpd', 2, ['2']).success  # ~30 s of simulated travel
    try:
        result, status, _ = ros.run_action(Home, srv('level'), Home.Goal(joint_names=['tilt']),
                                           timeout=60, cancel_after=1.5)
        assert status == GoalStatus.STATUS_CANCELED
        assert not result.success and 'cancelled' in result.message, result.message
        wait_for(lambda: sim_state(control_port)['axes']['2']['velocity'] == 0.0, 20.0,
                 'tilt stopped')
        assert sim_state(control_port)['axes']['2']['position'] > 5.0  # not levelled
    finally:
        assert command(ros, 'CFG_SetGeneralSpd', 2, ['30']).success


def test_level_refused_while_scanning(rig):
    ros, control_port = rig
    scan = ros.call(StartScan, srv('start_scan'), StartScan.Request(
        pattern='snake', pan_min=-0.2, pan_max=0.2, tilt_min=0.0, tilt_max=0.2, speed=0.5,
        tilt_step=0.1))
    assert scan.success, scan.message
    ros.wait_for_message(f'/{NODE}/status', GimbalStatus, lambda m: 'scanning' in m.mode,
                         timeout=10)
    requests_before = sim_state(control_port)['requests']
    result, _, _ = ros.run_action(Home, srv('level'), Home.Goal())
    assert not result.success and 'scan' in result.message
    drift, _, _ = ros.run_action(Home, srv('compensate_gyro_drift'), Home.Goal())
    assert not drift.success and 'scan' in drift.message
    assert sim_state(control_port)['scanning']  # nothing stopped or started it
    assert sim_state(control_port)['requests'] >= requests_before
    assert ros.call(Trigger, srv('stop'), Trigger.Request()).success


def test_level_refused_while_a_joint_moves(rig):
    ros, control_port = rig
    wait_at_rest(ros, control_port)
    ros.publish('joint_command', JointState(name=['pan'], velocity=[0.2]))
    ros.wait_for_message('joint_states', JointState, lambda m: abs(m.velocity[0]) > 0.1)
    result, _, _ = ros.run_action(Home, srv('level'), Home.Goal(joint_names=['tilt']))
    assert not result.success and 'pan moving' in result.message, result.message
    assert ros.call(Trigger, srv('stop'), Trigger.Request()).success


def test_gyro_drift_compensation_action(rig):
    ros, control_port = rig
    wait_at_rest(ros, control_port)
    named, _, _ = ros.run_action(Home, srv('compensate_gyro_drift'),
                                 Home.Goal(joint_names=['pan']))
    assert not named.success and 'no joint names' in named.message
    result, _, feedback = ros.run_action(Home, srv('compensate_gyro_drift'), Home.Goal(),
                                         timeout=60)
    assert result.success, result.message
    assert '0.05000 deg/s' in result.message  # the simulator's gyro bias
    wait_for(lambda: feedback, 10.0, 'drift feedback')
    assert 'measuring the gyro drift' in feedback[0].state
    assert sim_state(control_port)['gyro_drift']['2'] == pytest.approx(0.05)
    reset = ros.call(Trigger, srv('reset_gyro_drift'), Trigger.Request())
    assert reset.success, reset.message
    assert sim_state(control_port)['gyro_drift']['2'] == 0.0


def test_gyro_drift_aborts_when_the_pedestal_moves(rig):
    ros, control_port = rig
    wait_at_rest(ros, control_port)
    ros.publish('joint_command', JointState(name=['pan'], velocity=[0.0]))  # publisher ready

    def count() -> int:
        return int(control(control_port, 'count IMU_GyroDriftCompensation').split()[1])

    before = count()

    def jog_once_measuring() -> None:
        wait_for(lambda: count() > before, 30.0, 'the drift measurement to start')
        ros.publish('joint_command', JointState(name=['pan'], velocity=[0.2]))

    jogger = threading.Thread(target=jog_once_measuring, daemon=True)
    jogger.start()
    try:
        result, _, _ = ros.run_action(Home, srv('compensate_gyro_drift'), Home.Goal(),
                                      timeout=60)
    finally:
        jogger.join(30.0)
        assert ros.call(Trigger, srv('stop'), Trigger.Request()).success
    assert not result.success
    assert 'moved during the drift measurement' in result.message, result.message


def test_enable_switches_drives_and_status_shows_it(rig):
    ros, control_port = rig
    reply = ros.call(SetBool, srv('enable'), SetBool.Request(data=False))
    assert reply.success, reply.message
    state = sim_state(control_port)
    assert not state['axes']['1']['axis_on'] and not state['axes']['2']['axis_on']
    ros.wait_for_message(f'/{NODE}/status', GimbalStatus, lambda m: set(
        axis_states(m).values()) == {AxisState.STATE_DISABLED}, timeout=15)
    ros.wait_for_diagnostic(NODE, 'tilt', lambda s: 'SRL.axis_off' in {
        kv.key for kv in s.values})
    # interfaces that move the pedestal refuse on a drive that is off, sending nothing
    tracking = ros.call(SetMode, srv('set_tracking'), SetMode.Request(mode='auto'))
    assert not tracking.success and 'off' in tracking.message
    assert sim_state(control_port)['tracker_mode']['0'] == 0
    level, _, _ = ros.run_action(Home, srv('level'), Home.Goal(joint_names=['tilt']))
    assert not level.success and 'drive is off' in level.message
    reply = ros.call(SetBool, srv('enable'), SetBool.Request(data=True))
    assert reply.success, reply.message
    state = sim_state(control_port)
    assert state['axes']['1']['axis_on'] and state['axes']['2']['axis_on']
    ros.wait_for_message(f'/{NODE}/status', GimbalStatus, lambda m: AxisState.STATE_DISABLED
                         not in axis_states(m).values(), timeout=15)


def test_enable_refuses_a_faulted_drive(rig):
    ros, control_port = rig
    assert control(control_port, 'fault over_current 1') == 'ok'
    ros.wait_for_message(f'/{NODE}/status', GimbalStatus, lambda m: axis_states(m).get(
        'pan') == AxisState.STATE_FAULT, timeout=15)
    reply = ros.call(SetBool, srv('enable'), SetBool.Request(data=True))
    assert not reply.success and 'pan' in reply.message and 'reset_faults' in reply.message
    assert ros.call(Trigger, srv('reset_faults'), Trigger.Request()).success
    ros.wait_for_message(f'/{NODE}/status', GimbalStatus, lambda m: axis_states(m).get(
        'pan') not in (AxisState.STATE_FAULT, AxisState.STATE_DISABLED), timeout=15)
    msg = ros.wait_for_message('joint_states', JointState)
    assert set(joint_positions(msg)) == {'pan', 'tilt'}



def test_ranging_restarts_after_a_reconnect(rig):
    ros, control_port = rig
    assert ros.call(SetBool, srv('set_ranging'), SetBool.Request(data=True)).success
    starts = int(control(control_port, 'count LRF_StartMeasurement').split()[1])
    assert control(control_port, 'drop 1.0') == 'ok'
    ros.wait_for_diagnostic(NODE, 'connection', lambda s: s.level == b'\x02')
    ros.wait_for_diagnostic(NODE, 'connection', lambda s: s.level == b'\x00', timeout=30)
    wait_for(lambda: int(control(control_port, 'count LRF_StartMeasurement').split()[1])
             > starts, 15.0, 'LRF_StartMeasurement after the reconnect')
    ros.wait_for_message(f'/{NODE}/range', Range, timeout=15)
    assert ros.call(SetBool, srv('set_ranging'), SetBool.Request(data=False)).success


def test_controller_without_digital_io_is_not_polled_for_it(capture_rig):
    """Firmware before 2.22.0: no ~/digital_io, and setting an output names the NACK."""
    dio_topic, status_topic = f'/{NODE}/digital_io', f'/{NODE}/status'
    with capture_rig(['--no-digital-io'], ['digital_io_rate:=10.0', 'status_period:=0.2'],
                     record=[(dio_topic, UInt8MultiArray), (status_topic, GimbalStatus)]
                     ) as (started, control_port):
        ros = started.ros
        dio, statuses = started.recorded[dio_topic], started.recorded[status_topic]
        wait_for(lambda: len(statuses) >= 20, 30.0, '~/status messages (2 s)')
        assert dio == []
        polled = int(control(control_port, 'count COM_getDigitalIO').split()[1])
        assert polled == 1  # the probe at connect, nothing after
        reply = ros.call(SetBool, srv('set_digital_output_1'), SetBool.Request(data=True))
        assert not reply.success and 'NACK 0xA6' in reply.message
