"""capture_driver_node as a process against capture_sim as a process, through rclpy.

Needs the colcon-built workspace (make build; source scripts/ros_env.sh). One simulator
and one node serve the whole module; tests run in file order (link drop last). Waits are
"up to a timeout", never timing assertions.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')
from rcl_interfaces.msg import Log
from sensor_msgs.msg import Imu, JointState, NavSatFix
from std_srvs.srv import SetBool, Trigger

from capture_driver.sim import console_state as sim_state
from capture_driver.sim import control
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.ros import joint_positions, node_refusing_to_start
from gimbal_msgs.action import Home, MoveTo
from gimbal_msgs.msg import GimbalStatus
from gimbal_msgs.srv import (
    ClearPreset,
    DeviceCommand,
    GotoPreset,
    ListPresets,
    SetMode,
    SetPreset,
    StartScan,
)

pytestmark = pytest.mark.ros

PKG = 'capture_driver'
NODE = 'capture_driver'


def srv(name: str) -> str:
    return f'/{NODE}/{name}'


@pytest.fixture(scope='module')
def rig(capture_rig):
    with capture_rig(
            ['--time-scale', '4'],
            ['publish_rate:=20.0', 'reconnect_period:=0.3', 'diagnostics_period:=0.25',
             'status_period:=0.2', 'command_timeout:=0.4', 'imu_rate:=5.0', 'fix_rate:=2.0',
             'default_speed:=1.0', 'acceleration:=6.0'],
            record=[('/rosout', Log)], node_log_tail=4000) as (started, control_port):
        yield started.ros, control_port, started.node, started.recorded['/rosout']





def wait_position(ros, targets: dict[str, float], tolerance=2e-3, timeout=20.0):
    return ros.wait_for_message(
        'joint_states', JointState,
        lambda m: all(abs(joint_positions(m).get(j, math.inf) - p) < tolerance
                      for j, p in targets.items()), timeout=timeout)


def test_joint_states_and_identity(rig):
    ros, *_ = rig
    msg = ros.wait_for_message('joint_states', JointState)
    assert msg.name == ['pan', 'tilt']
    assert len(msg.velocity) == 2
    status = ros.wait_for_diagnostic(NODE, 'connection', lambda s: s.level == b'\x00')
    # part number, serial number, hardware revision and firmware, all read from the device
    assert status.hardware_id == 'capture-pnCAP-PT2-SIM-sn24017-hw3.1-fw2.24.0'
    values = {kv.key: kv.value for kv in status.values}
    assert values['serial_number'] == '24017'
    assert values['firmware'].startswith('2.24.0')
    # motor current (MOT_GetMotorCurrent) in ~/status, A; no effort without torque_constants
    ros.wait_for_message(srv('status'), GimbalStatus,
                         lambda m: all(math.isfinite(a.current) for a in m.axes))
    assert not ros.wait_for_message('joint_states', JointState).effort
    ros.wait_for_diagnostic(NODE, 'joint_states frequency', lambda s: s.level == b'\x00')


def test_move_to_reaches_target_and_joint_states_show_it(rig):
    ros, control_port, *_ = rig
    goal = MoveTo.Goal(joint_names=['pan', 'tilt'], positions=[0.4, -0.2])
    result, _, feedback = ros.run_action(MoveTo, srv('move_to'), goal, timeout=40)
    assert result.success, result.message
    assert feedback
    wait_position(ros, {'pan': 0.4, 'tilt': -0.2})
    # REP-103: positive pan is counter-clockwise; Capture yaw counts clockwise.
    state = sim_state(control_port)
    assert state['axes']['1']['position'] == pytest.approx(-math.degrees(0.4), abs=0.05)






def test_a_joint_command_stream_is_written_without_waiting_for_acks(rig):
    """Once a move has set the axis up, a command of a stream at that speed goes out as
    MOT_SendPosition + MOT_Update in one write from the callback, when no other request
    holds the link at that moment (the poll, status and sensor reads of this rig often do,
    so the stream goes on until one is posted); the command thread reads the ACKs.
    ``link.posted_moves`` in the device diagnostics counts them."""
    ros, *_ = rig

    def posted(status) -> int:
        return int({kv.key: kv.value for kv in status.values}['link.posted_moves'])

    before = posted(ros.wait_for_diagnostic(NODE, 'device'))
    for step in range(30):  # the first may need the whole set-up
        target = 0.10 + 0.02 * (step % 4)
        ros.publish('joint_command', JointState(name=['tilt'], position=[target]))
        wait_position(ros, {'tilt': target})
        status = ros.wait_for_diagnostic(NODE, 'device')
        if posted(status) > before:
            break
    values = {kv.key: kv.value for kv in status.values if kv.key.startswith('link')}
    assert posted(status) > before, values


def test_home_action_uses_device_homing(rig):
    ros, control_port, *_ = rig
    control(control_port, 'pose 1 20')
    result, _, feedback = ros.run_action(Home, srv('home'), Home.Goal(), timeout=60)
    assert result.success, result.message
    assert any('homing' in f.state for f in feedback)
    wait_position(ros, {'pan': 0.0, 'tilt': 0.0})


def test_device_presets(rig):
    ros, control_port, *_ = rig
    reply = ros.call(SetPreset, srv('set_preset'), SetPreset.Request(
        index=2, name='gate', joint_names=['pan', 'tilt'], positions=[-0.3, 0.25]))
    assert reply.success, reply.message
    reply = ros.call(SetPreset, srv('set_preset'), SetPreset.Request(
        index=3, name='here', use_current_position=True))
    assert reply.success, reply.message
    listed = ros.call(ListPresets, srv('list_presets'), ListPresets.Request())
    assert listed.success
    by_index = {p.index: p for p in listed.presets}
    assert by_index[2].name == 'gate'
    assert by_index[2].positions[0] == pytest.approx(-0.3, abs=1e-4)
    assert sim_state(control_port)['presets'] == [2, 3]
    reply = ros.call(GotoPreset, srv('goto_preset'), GotoPreset.Request(index=2, speed=0.8))
    assert reply.success, reply.message
    wait_position(ros, {'pan': -0.3, 'tilt': 0.25})
    bad = ros.call(GotoPreset, srv('goto_preset'), GotoPreset.Request(index=9))
    assert not bad.success and 'empty' in bad.message
    loop = ros.call(Trigger, srv('start_preset_loop'), Trigger.Request())
    assert loop.success, loop.message
    wait_for(lambda: sim_state(control_port)['preset_looping'], 10.0, 'looping')
    stop = ros.call(Trigger, srv('stop_preset_loop'), Trigger.Request())
    assert stop.success, stop.message
    assert not sim_state(control_port)['preset_looping']
    cleared = ros.call(ClearPreset, srv('clear_preset'), ClearPreset.Request(index=3))
    assert cleared.success
    assert sim_state(control_port)['presets'] == [2]


def test_device_scan_and_stop(rig):
    ros, control_port, *_ = rig
    refused = ros.call(StartScan, srv('start_scan'), StartScan.Request(
        pattern='sector', pan_min=-0.2, pan_max=0.2, speed=0.3))
    assert not refused.success and 'zigzag' in refused.message
    too_wide = ros.call(StartScan, srv('start_scan'), StartScan.Request(
        pattern='zigzag', pan_min=-5.0, pan_max=0.2, tilt_min=0.0, tilt_max=0.2, speed=0.3,
        tilt_step=0.1))
    assert not too_wide.success and 'joint limits' in too_wide.message
    reply = ros.call(StartScan, srv('start_scan'), StartScan.Request(
        pattern='snake', pan_min=-0.2, pan_max=0.2, tilt_min=0.0, tilt_max=0.2, speed=0.5,
        tilt_step=0.1))
    assert reply.success, reply.message
    assert sim_state(control_port)['scanning']
    ros.wait_for_message(
        '~/status'.replace('~', f'/{NODE}'), GimbalStatus, lambda m: 'scanning' in m.mode,
        timeout=10)
    stop = ros.call(Trigger, srv('stop_scan'), Trigger.Request())
    assert stop.success, stop.message
    assert not sim_state(control_port)['scanning']
    # A move after a scan works (the driver left scan mode).
    goal = MoveTo.Goal(joint_names=['pan'], positions=[0.1])
    result, _, _ = ros.run_action(MoveTo, srv('move_to'), goal, timeout=40)
    assert result.success, result.message


def test_nack_surfaces_as_clear_service_error(rig):
    ros, control_port, *_ = rig
    assert control(control_port, 'nack STB_StabilizationOn 1 E6') == 'ok'
    reply = ros.call(SetBool, srv('set_stabilization'), SetBool.Request(data=True))
    assert not reply.success
    assert 'NACK 0xE6' in reply.message and 'Execution error' in reply.message
    reply = ros.call(SetBool, srv('set_stabilization'), SetBool.Request(data=True))
    assert reply.success, reply.message
    reply = ros.call(SetBool, srv('set_stabilization'), SetBool.Request(data=False))
    assert reply.success, reply.message
    assert control(control_port, 'nack MOT_Update 1 A6') == 'ok'
    goal = MoveTo.Goal(joint_names=['tilt'], positions=[0.05])
    result, _, _ = ros.run_action(MoveTo, srv('move_to'), goal, timeout=40)
    assert not result.success
    assert 'NACK 0xA6' in result.message and 'Invalid command' in result.message


def test_command_service(rig):
    ros, *_ = rig

    def run(name, axis=0, args=()):
        return ros.call(DeviceCommand, srv('command'), DeviceCommand.Request(
            command=name, axis=axis, arguments=list(args)))

    fw = run('COM_GetFw')
    assert fw.success and fw.results == ['2.24.0']
    speed = run('MOT_GetMotorSpeed', 1)
    assert speed.success and speed.results[0].endswith('deg/s')
    assert run('PRST_SetLoopingDelay', 0, ['160']).success
    assert run('PRST_GetLoopingDelay').results == ['160 ms']
    refused = run('COM_Reboot')
    assert not refused.success and 'allow_reboot' in refused.message
    refused = run('MOT_SendPosition', 1, ['10'])
    assert not refused.success and 'move_to' in refused.message
    unknown = run('GPS_GetAltitude')
    assert not unknown.success and 'not established' in unknown.message
    bad = run('MOT_SetSpeed', 1, ['fast'])
    assert not bad.success and 'bad argument' in bad.message
    bad_axis = run('MOT_GetLoadPosition', 9)
    assert not bad_axis.success and 'outside 1..3' in bad_axis.message
    # Typed groups the second witness and the document settle.
    assert run('STB_SetSpdKp', 2, ['1.5']).success
    assert run('STB_GetSpdKp', 2).results == ['1.5 factor']
    assert run('PELCOD_SetMaxSpd', 1, ['40']).success
    assert run('PELCOD_GetMaxSpd', 1).results == ['40 deg/s']
    refused = run('VDT_setTrackingOn', 1, ['2'])  # moves the axes: ~/set_tracking checks
    assert not refused.success and '~/set_tracking' in refused.message, refused.message
    assert run('VDT_isAutoModeOn', 1).results == ['False flag']  # camera 1, group byte
    assert run('VDT_GetTargetsList', 1).results == [f'target{i}=0x0' for i in range(1, 6)]
    assert run('DG_GetBoresightOffset', 3).message.count('1, 2, 4, 5') == 1
    for name, args, opt_in in (('PELCOD_SetAddress', ['5'], 'allow_network_config'),
                               ('STB_SaveStabilizationCfg', [], 'allow_nv_write')):
        refused = run(name, 0, args)
        assert not refused.success and opt_in in refused.message, refused.message


def test_imu_and_fix_topics(rig):
    ros, *_ = rig
    imu = ros.wait_for_message(f'/{NODE}/imu', Imu, timeout=15)
    norm = math.sqrt(imu.orientation.x ** 2 + imu.orientation.y ** 2 + imu.orientation.z ** 2
                     + imu.orientation.w ** 2)
    assert norm == pytest.approx(1.0)
    fix = ros.wait_for_message(f'/{NODE}/fix', NavSatFix, timeout=15)
    assert fix.latitude == pytest.approx(32.1040, abs=1e-6)
    assert fix.longitude == pytest.approx(34.8915, abs=1e-6)


def test_sensor_reads_only_while_someone_subscribes(rig):
    """~/imu (imu_rate 5 Hz) reads the IMU only while its topic has a subscriber: six
    request/reply transactions per reading that would otherwise take the link."""
    ros, control_port, *_ = rig
    topic = f'/{NODE}/imu'

    def imu_reads() -> int:
        return int(control(control_port, 'count IMU_GetRoll').split()[1])

    def reads_over(states: int) -> int:
        """IMU reads while the node publishes ``states`` more joint_states (20 Hz)."""
        before = imu_reads()
        ros.wait_for_message('joint_states', JointState)
        seen = ros.subscribe('joint_states', JointState)
        start = len(seen)
        wait_for(lambda: len(seen) >= start + states, 15.0, f'{states} joint_states')
        return imu_reads() - before

    ros.unsubscribe(topic)  # whatever an earlier test left
    # discovery tells the node the subscriber left; then no read for 1 s (5 IMU periods)
    wait_for(lambda: reads_over(10) == 0, 15.0, 'IMU reads to stop without a subscriber')
    assert reads_over(20) == 0
    ros.wait_for_message(topic, Imu, timeout=15)
    assert reads_over(20) > 0
    ros.unsubscribe(topic)
    wait_for(lambda: reads_over(10) == 0, 15.0, 'IMU reads to stop again')


def test_goto_lla_points_at_target(rig):
    ros, *_ = rig
    # ~100 m north-east of the simulated GPS position, same altitude.
    target = NavSatFix(latitude=32.1040 + 0.0006, longitude=34.8915 + 0.0007, altitude=65.43)
    ros.publish(f'/{NODE}/goto_lla', target)
    msg = ros.wait_for_message(
        'joint_states', JointState,
        lambda m: joint_positions(m)['pan'] < -0.5 and all(v == 0.0 for v in m.velocity),
        timeout=20)
    assert joint_positions(msg)['tilt'] == pytest.approx(0.0, abs=1e-3)


def test_emergency_stop(rig):
    ros, control_port, *_ = rig
    reply = ros.call(SetBool, srv('set_emergency_stop'), SetBool.Request(data=True))
    assert reply.success, reply.message
    assert sim_state(control_port)['emergency_stop']
    ros.wait_for_diagnostic(NODE, 'device', lambda s: 'emergency stop' in s.message)
    goal = MoveTo.Goal(joint_names=['tilt'], positions=[0.1])
    result, _, _ = ros.run_action(MoveTo, srv('move_to'), goal, timeout=40)
    assert not result.success and 'Emergency stop' in result.message
    reply = ros.call(SetBool, srv('set_emergency_stop'), SetBool.Request(data=False))
    assert reply.success, reply.message
    result, _, _ = ros.run_action(MoveTo, srv('move_to'), goal, timeout=40)
    assert result.success, result.message


def test_fault_reported_then_reset(rig):
    ros, control_port, *_ = rig
    assert control(control_port, 'fault over_current 1') == 'ok'
    status = ros.wait_for_diagnostic(NODE, 'pan', lambda s: s.level == b'\x02')
    keys = {kv.key for kv in status.values}
    assert 'CMER.over_current' in keys and 'SRH.fault' in keys
    device = ros.wait_for_diagnostic(
        NODE, 'device', lambda s: 'No communication with axes' in s.message)
    assert any(kv.key == 'error.ERR_GetDriverErrorString' for kv in device.values)
    reply = ros.call(Trigger, srv('reset_faults'), Trigger.Request())
    assert reply.success, reply.message
    ros.wait_for_diagnostic(NODE, 'pan', lambda s: s.level == b'\x00')


MOTION_COMMANDS = ('MOT_SendPosition', 'MOT_Update', 'MOT_SetSpeed', 'PRST_GoToPreset',
                   'SCN_StartScanZigZag', 'SCN_StartScanSnake', 'DG_GoToCamera')


def motion_sent(control_port: int) -> dict[str, int]:
    counts = sim_state(control_port)['requests_by_command']
    return {name: counts.get(name, 0) for name in MOTION_COMMANDS}


def assert_motion_refused(ros, control_port, reason: str) -> None:
    """joint_command, move_to, goto_preset, start_scan and ~/command motion on the pan axis
    are refused naming ``reason``, and the simulator receives no motion command."""
    before = motion_sent(control_port)
    ros.publish('joint_command', JointState(name=['pan'], position=[0.3]))
    goal = MoveTo.Goal(joint_names=['pan', 'tilt'], positions=[0.3, 0.0])
    result, _, _ = ros.run_action(MoveTo, srv('move_to'), goal, timeout=40)
    assert not result.success and reason in result.message, result.message
    reply = ros.call(GotoPreset, srv('goto_preset'), GotoPreset.Request(index=2))
    assert not reply.success and reason in reply.message, reply.message
    reply = ros.call(StartScan, srv('start_scan'), StartScan.Request(
        pattern='snake', pan_min=-0.2, pan_max=0.2, tilt_min=0.0, tilt_max=0.2, speed=0.5,
        tilt_step=0.1))
    assert not reply.success and reason in reply.message, reply.message
    reply = ros.call(DeviceCommand, srv('command'), DeviceCommand.Request(
        command='DG_GoToCamera'))
    assert not reply.success and reason in reply.message, reply.message
    assert motion_sent(control_port) == before
    assert not sim_state(control_port)['scanning']


def test_motion_on_faulted_or_off_axis_is_refused_and_reset_quotes_device(rig):
    ros, control_port, *_ = rig
    assert control(control_port, 'fault over_current 1') == 'ok'
    status = ros.wait_for_diagnostic(NODE, 'pan', lambda s: s.level == b'\x02')
    assert 'SRH.fault' in {kv.key for kv in status.values}
    assert_motion_refused(ros, control_port, 'pan is faulted')
    stop_tracking = ros.call(SetMode, srv('set_tracking'), SetMode.Request(mode='off'))
    assert stop_tracking.success, stop_tracking.message  # switching off is never refused
    # A device that does not know MOT_ResetFaults: the reply quotes its answer.
    assert control(control_port, 'unknown MOT_ResetFaults') == 'ok'
    try:
        reply = ros.call(Trigger, srv('reset_faults'), Trigger.Request())
    finally:
        assert control(control_port, 'unknown MOT_ResetFaults off') == 'ok'
    assert not reply.success
    assert 'MOT_ResetFaults (axis 1): NACK 0xA6' in reply.message, reply.message
    assert 'Opcode not Recognized' in reply.message, reply.message
    assert_motion_refused(ros, control_port, 'pan is faulted')
    reply = ros.call(Trigger, srv('reset_faults'), Trigger.Request())
    assert reply.success, reply.message
    assert 'ACKed MOT_ResetFaults' in reply.message and 'pan on, no fault' in reply.message
    # Drive switched off: refused with the axis state, on again after reset_faults.
    off = ros.call(DeviceCommand, srv('command'), DeviceCommand.Request(
        command='MOT_AxisOff', axis=1))
    assert off.success, off.message
    ros.wait_for_diagnostic(NODE, 'pan', lambda s: any(
        kv.key == 'SRL.axis_off' for kv in s.values))
    assert_motion_refused(ros, control_port, 'pan drive is off')
    reply = ros.call(Trigger, srv('reset_faults'), Trigger.Request())
    assert reply.success, reply.message
    assert sim_state(control_port)['axes']['1']['axis_on']
    goal = MoveTo.Goal(joint_names=['pan'], positions=[0.05])
    result, _, _ = ros.run_action(MoveTo, srv('move_to'), goal, timeout=40)
    assert result.success, result.message






@pytest.mark.parametrize(('override', 'name'), [
    ('axis_ids:=[1,1]', 'axis_ids'),
    ('joint_directions:=[1.0,0.5]', 'joint_directions'),
    ('transport:=udp', 'transport'),
    ('range_min:=6000.0', 'range_min'),  # range_max defaults to 5000 m
    ('digital_outputs:=[2,7]', 'digital_outputs'),
    ('digital_outputs:=[3,3]', 'digital_outputs'),
    ('tracker_camera:=4', 'tracker_camera'),
])
def test_invalid_parameters_are_refused_naming_them(override, name):
    output = node_refusing_to_start(PKG, 'capture_driver_node', [override])
    assert name in output
