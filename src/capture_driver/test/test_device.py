"""GimbalController + CaptureDevice against the simulator in-process, over its real
transports (TCP loopback and a pty); no ROS.

Waits are "up to a timeout" for a condition, never timing assertions.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections.abc import Callable, Iterator, Sequence

import pytest

from capture_driver.device import CaptureDevice, CaptureSettings
from capture_driver.errors import DeviceNack, NotConnected
from capture_driver.protocol import BY_OPCODE, COMMANDS
from capture_driver.sim import CaptureSimulator, PedestalModel
from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.device import AxisStateCode
from gimbal_driver_common.diagnostics import Level
from gimbal_driver_common.errors import DeviceRefused, InvalidRequest, LinkError
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.policies import Motion
from gimbal_driver_common.scan import ScanRequest
from gimbal_driver_testing import wait_for

JOINTS = ['pan', 'tilt']
LOG = logging.getLogger('test_device')


@pytest.fixture
def sim():
    simulator = CaptureSimulator(PedestalModel(time_scale=8.0), tcp_port=0, pty=True).start()
    yield simulator
    simulator.stop()


def make_config(command_timeout: float = 0.5) -> ControllerConfig:
    return ControllerConfig(
        joint_names=list(JOINTS),
        limits={'pan': JointLimits(-math.pi, math.pi, 1.5),
                'tilt': JointLimits(-math.pi / 2, math.pi / 2, 1.5)},
        publish_rate=20.0, command_timeout=command_timeout, reconnect_period=0.2,
        goal_tolerance=2e-3, move_timeout=30.0)


def make_settings(sim, transport: str = 'tcp', **overrides) -> CaptureSettings:
    link = ({'host': '127.0.0.1', 'port': sim.tcp.port} if transport == 'tcp'
            else {'serial_port': sim.pty.port_name})
    values = dict(joint_names=list(JOINTS), axis_ids=[1, 2], joint_directions=[-1.0, 1.0],
                  gear_ratios=[1.0, 1.0], transport=transport, keepalive_period=0.0,
                  default_speed=1.0, acceleration=6.0, status_period=0.1, **link)
    values.update(overrides)
    return CaptureSettings(**values)


class Rig:
    """One device, its controller (open and active) and the motion policies."""

    def __init__(self, sim, transport: str = 'tcp', command_timeout: float = 0.5) -> None:
        self.sim = sim
        self.config = make_config(command_timeout)
        self.device = CaptureDevice(make_settings(sim, transport))
        self.controller = GimbalController(self.device, self.config, LOG)
        self.motion = Motion(self.controller, scan_patterns=self.device.capabilities.scans
                             .patterns)
        self.controller.open()
        self.controller.activate()
        wait_for(lambda: self.controller.latest is not None, 10.0, 'first sample')

    def close(self) -> None:
        self.controller.shutdown()

    def sim_axis(self, axis: int):
        return self.sim.model.axes[axis]

    def sent(self, name: str) -> int:
        opcode = COMMANDS[name].opcode
        return self.sim.model.request_counts[opcode]

    def wait_positions(self, targets: dict[str, float], tolerance: float = 2e-3,
                       timeout: float = 20.0) -> None:
        def there() -> bool:
            current = self.controller.positions()
            return all(abs(current.get(j, math.inf) - p) <= tolerance
                       for j, p in targets.items())

        wait_for(there, timeout, f'joints at {targets}')


@pytest.fixture(params=['tcp', 'pty'])
def rig(request, sim):
    rig = Rig(sim, request.param)
    yield rig
    rig.close()


@pytest.fixture
def tcp_rig(sim):
    rig = Rig(sim, 'tcp', command_timeout=0.3)
    yield rig
    rig.close()


def test_connect_reads_the_identity(tcp_rig):
    ctl = tcp_rig.controller
    assert ctl.connected
    info = ctl.device_info
    assert info.serial_number == '24017'
    assert info.firmware_version.startswith('2.24.0')
    assert info.hardware_id == 'capture-pnCAP-PT2-SIM-sn24017-hw3.1-fw2.24.0'
    assert tcp_rig.device.description() == f'tcp://127.0.0.1:{tcp_rig.sim.tcp.port}'
    assert tcp_rig.device.functions.has_imu and tcp_rig.device.functions.has_gps


def _device_part(rig):
    return next(p for p in rig.device.capabilities.status.parts() if p.part == 'device')


@pytest.mark.parametrize('drops_queued', [False, True])
def test_poll_reads_batched_or_falls_back_and_says_so_without_a_warning(sim, drops_queued):
    """A controller that drops queued requests is read one request at a time after three
    incomplete batches; the poll goes on, and diagnostics say how it reads (level OK)."""
    sim.model.one_request_per_read = drops_queued
    rig = Rig(sim, 'tcp')
    try:
        sim.model.set_pose(1, 20.0)
        rig.wait_positions({'pan': -math.radians(20.0)})
        expected = ('one request at a time (batched reads came back incomplete)'
                    if drops_queued else 'batched (one write per poll)')
        wait_for(lambda: dict(_device_part(rig).values).get('link.reads') == expected, 10.0,
                 f'link.reads = {expected}')
        sim.model.set_pose(1, -5.0)
        rig.wait_positions({'pan': math.radians(5.0)})  # still polling
        # OK while it says how it reads: a status register answered after its 0.5 s on a
        # loaded machine (the simulator shares this process) is named unanswered at WARN
        # until it is asked again after its back-off (issue 45), a WARN of that read, not
        # of the way the poll reads; the way it reads never leaves OK
        try:
            wait_for(lambda: _device_part(rig).level == Level.OK, 30.0, 'device status OK')
        except TimeoutError:
            raise AssertionError(f'device status: {_device_part(rig).message}') from None
        assert dict(_device_part(rig).values).get('link.reads') == expected
        assert rig.device.client.batching is not drops_queued
    finally:
        rig.close()


def test_positions_convert_from_device_degrees_and_signs(tcp_rig):
    tcp_rig.sim.model.set_pose(1, 30.0)  # yaw 30 deg clockwise
    tcp_rig.sim.model.set_pose(2, -12.0)  # pitch 12 deg down
    tcp_rig.wait_positions({'pan': -math.radians(30.0), 'tilt': math.radians(-12.0)})


def test_move_converges_with_rep103_signs_on_the_device(rig):
    targets = rig.motion.start_move(JOINTS, [0.4, -0.2])
    outcome = rig.motion.wait_move(targets)
    assert outcome.success, outcome.message
    # REP-103 pan is counter-clockwise; Capture yaw counts clockwise (joint_directions -1)
    assert rig.sim_axis(1).position == pytest.approx(-math.degrees(0.4), abs=0.05)
    assert rig.sim_axis(2).position == pytest.approx(math.degrees(-0.2), abs=0.05)
    assert rig.controller.commanded_targets == pytest.approx({'pan': 0.4, 'tilt': -0.2})


def test_jog_converts_the_speed_and_the_watchdog_stops_it(tcp_rig):
    ctl = tcp_rig.controller
    ctl.command(['pan'], [], [0.3])
    # +0.3 rad/s pan (counter-clockwise) is a negative yaw speed on the device
    wait_for(lambda: tcp_rig.sim_axis(1).velocity < -1.0, 10.0, 'device jogging clockwise-')
    wait_for(lambda: ctl.latest.velocities['pan'] > 0.1, 10.0, 'positive pan velocity')
    # no further joint_command: the dead-man watchdog (0.3 s) stops the axis
    wait_for(lambda: tcp_rig.sim_axis(1).velocity == 0.0, 10.0, 'jog stopped by the watchdog')
    assert not ctl.watchdog.jogging
    wait_for(lambda: not ctl.moving('pan'), 10.0, 'pan at rest in the samples')


def test_stop_ends_a_move_and_halts_every_axis(tcp_rig):
    ctl, motion = tcp_rig.controller, tcp_rig.motion
    targets = motion.start_move(['pan'], [-2.5], [0.2])
    wait_for(lambda: tcp_rig.sim_axis(1).velocity != 0.0, 10.0, 'moving')
    outcome: list = []
    waiter = threading.Thread(target=lambda: outcome.append(motion.wait_move(targets)))
    waiter.start()
    assert 'stopped' in ctl.stop()
    waiter.join(30.0)
    assert outcome and outcome[0].state == 'stopped'
    wait_for(lambda: all(a.velocity == 0.0 for a in tcp_rig.sim.model.axes.values()), 10.0,
             'axes at rest')
    assert abs(tcp_rig.sim_axis(1).position - math.degrees(2.5)) > 10.0  # not reached


def test_faulted_and_off_axes_are_refused_with_the_reason_and_nothing_sent(tcp_rig):
    ctl, motion, device = tcp_rig.controller, tcp_rig.motion, tcp_rig.device
    tcp_rig.sim.model.inject_fault(1, 'over_current')
    wait_for(lambda: ctl.refusal(['pan']) is not None, 10.0, 'fault seen in the registers')
    assert 'pan is faulted' in ctl.refusal(['pan'])
    assert ctl.refusal(['tilt']) is None
    assert device.capabilities.status.axis_details('pan')['state'] == AxisStateCode.FAULT
    before = tcp_rig.sent('MOT_SendPosition'), tcp_rig.sent('MOT_Update')
    with pytest.raises(DeviceRefused, match='pan is faulted'):
        motion.start_move(JOINTS, [0.3, 0.0])
    with pytest.raises(DeviceRefused, match='pan is faulted'):
        ctl.command(['pan'], [0.3], [])
    with pytest.raises(DeviceRefused, match='pan is faulted'):
        motion.start_scan(ScanRequest('snake', -0.2, 0.2, 0.0, 0.2, 0.5, 0.1, 0.0))
    assert (tcp_rig.sent('MOT_SendPosition'), tcp_rig.sent('MOT_Update')) == before
    message = ctl.reset_faults()
    assert 'ACKed MOT_ResetFaults' in message and 'pan on, no fault' in message
    assert ctl.refusal(['pan']) is None
    # a drive switched off: refused with the axis state
    ctl.call(lambda: device.functions.set_power(False))
    wait_for(lambda: 'pan drive is off' in (ctl.refusal(['pan']) or ''), 10.0, 'drive off')
    ctl.call(lambda: device.functions.set_power(True))
    wait_for(lambda: ctl.refusal(JOINTS) is None, 10.0, 'drives on again')


def test_device_nack_is_a_refusal_carrying_the_devices_reason(tcp_rig):
    assert tcp_rig.sim.control('nack MOT_Update 1 A6') == 'ok'
    with pytest.raises(DeviceNack) as info:
        tcp_rig.motion.start_move(['tilt'], [0.05])
    assert isinstance(info.value, DeviceRefused)
    assert 'NACK 0xA6' in str(info.value) and 'Invalid command' in str(info.value)


def test_invalid_requests_send_nothing(tcp_rig):
    ctl, device = tcp_rig.controller, tcp_rig.device
    before = len(tcp_rig.sim.model.requests)
    with pytest.raises(InvalidRequest, match='preset index 16'):
        ctl.call(lambda: device.capabilities.presets.set(16, 'x', {'pan': 0.0}))
    with pytest.raises(InvalidRequest, match='bad argument'):
        ctl.call(lambda: device.functions.command('MOT_SetSpeed', 1, ['fast']))
    with pytest.raises(DeviceRefused, match='allow_reboot'):
        ctl.call(lambda: device.functions.command('COM_Reboot', 0, []))
    with pytest.raises(InvalidRequest, match='latitude'):
        ctl.call(lambda: device.functions.goto_lla(91.0, 0.0, 0.0))
    # only the controller's own polls reached the device
    polls = {COMMANDS[n].opcode for n in ('MOT_GetLoadPosition', 'MOT_GetMotorSpeed',
                                           'MOT_GetMotorCurrent')}
    sent = [f for f in list(tcp_rig.sim.model.requests)[before:] if f.opcode not in polls]
    assert all(COMMANDS['MOT_SetSpeed'].opcode != f.opcode for f in sent)
    assert all(COMMANDS['PRST_SetPreset'].opcode != f.opcode for f in sent)
    assert all(COMMANDS['COM_Reboot'].opcode != f.opcode for f in sent)


def test_preset_slots_convert_both_ways(tcp_rig):
    ctl, motion = tcp_rig.controller, tcp_rig.motion
    motion.set_preset(2, 'gate', {'pan': -0.3, 'tilt': 0.25})
    record = tcp_rig.sim.model.presets[2]
    assert record.angles[0] == pytest.approx(math.degrees(0.3), abs=1e-3)  # yaw clockwise
    assert record.angles[1] == pytest.approx(math.degrees(0.25), abs=1e-3)
    listed = {p.index: p for p in motion.list_presets()}
    assert listed[2].positions == pytest.approx({'pan': -0.3, 'tilt': 0.25}, abs=1e-4)
    assert 'device preset 2' in motion.goto_preset(2, 0.8)
    assert ctl.commanded_targets == pytest.approx({'pan': -0.3, 'tilt': 0.25}, abs=1e-4)
    tcp_rig.wait_positions({'pan': -0.3, 'tilt': 0.25})
    with pytest.raises(DeviceRefused, match='empty'):
        motion.goto_preset(9, 0.0)
    assert 'cleared' in motion.clear_preset(2)
    assert 2 not in tcp_rig.sim.model.presets


def test_device_scan_converts_limits_and_stop_ends_it(tcp_rig):
    ctl, motion = tcp_rig.controller, tcp_rig.motion
    message = motion.start_scan(ScanRequest('snake', -0.2, 0.2, 0.0, 0.2, 0.5, 0.1, 0.0))
    assert message.startswith('device snake scan started')
    params = tcp_rig.sim.model.scan_params
    assert (params['yaw_min'], params['yaw_max']) == pytest.approx(
        (-math.degrees(0.2), math.degrees(0.2)), abs=1e-3)
    assert params['speed'] == pytest.approx(math.degrees(0.5), abs=1e-3)
    assert tcp_rig.sim.model.scan is not None
    before = len(tcp_rig.sim.model.requests)
    assert ctl.stop().startswith('all axes stopped')  # the axes' 0xA6 while scanning: no failure
    assert tcp_rig.sim.model.scan is None
    # issue 44: the axes are told to stop before the scan stop, whose answer may take 500 ms
    log = [BY_OPCODE[f.opcode].name for f in list(tcp_rig.sim.model.requests)[before:]
           if f.opcode in BY_OPCODE]
    assert log.index('MOT_Update') < log.index('SCN_StopScan')
    assert log.count('SCN_StopScan') == 1  # the whole stop once (stopped_by_device_stop)
    # the axes refused their steps while scanning: the next jog sets speed mode itself
    tcp_rig.device.jog({'pan': 0.3})  # the adapter's own jog: no dead-man stop ends it
    wait_for(lambda: tcp_rig.sim_axis(1).velocity != 0.0, 10.0, 'the jog after the scan')
    ctl.stop()
    with pytest.raises(InvalidRequest, match='zigzag'):
        motion.start_scan(ScanRequest('sector', -0.2, 0.2, 0.0, 0.0, 0.3, 0.1, 0.0))


@pytest.mark.parametrize('request_fields, reason', [
    (('zigzag', -0.2, 0.2, 0.0, 2.0, 0.5, 0.1, 0.0), 'tilt range .* outside the joint limits'),
    (('snake', -0.2, 0.2, 0.0, 0.2, 0.5, 0.0, 0.0), 'tilt_step 0.0 must be > 0'),
    (('square', -0.2, 0.2, 0.0, 0.2, 9.0, 0.1, 0.0), 'speed 9.0000 exceeds pan velocity_max'),
    (('zigzag', 0.3, -0.3, 0.0, 0.2, 0.5, 0.1, 0.0), 'pan_min 0.3000 > pan_max'),
    (('zigzag', -0.2, 0.2, -1.5, 1.5, 0.5, 0.01, 0.0), '300 rows exceed the device maximum 255'),
])
def test_device_scan_requests_are_checked_before_anything_is_sent(tcp_rig, request_fields,
                                                                   reason):
    """The core's scan check (scan.check_scan) and then the device's own (at most 255 rows):
    a refused scan sends nothing."""
    before = len(tcp_rig.sim.model.requests)
    with pytest.raises(InvalidRequest, match=reason):
        tcp_rig.motion.start_scan(ScanRequest(*request_fields))
    sent = [BY_OPCODE[frame.opcode].name for frame in tcp_rig.sim.model.requests[before:]]
    assert not [name for name in sent if name.startswith('SCN_')]


def test_imu_reading_is_rep103(tcp_rig):
    device = tcp_rig.device
    model = tcp_rig.sim.model
    reading = tcp_rig.controller.call(device.functions.imu)
    raw = tcp_rig.controller.call(device.client.imu)
    assert reading.yaw == pytest.approx(-math.radians(raw['yaw']), abs=1e-6)
    assert reading.pitch == pytest.approx(math.radians(raw['pitch']), abs=1e-6)
    fix = tcp_rig.controller.call(device.functions.gps_fix)
    assert (fix.latitude, fix.longitude) == pytest.approx(
        (model.gps_position.latitude, model.gps_position.longitude), abs=1e-6)


def test_link_drop_then_the_controller_reconnects(rig):
    """The controller's supervisor is the only reconnect loop: the client raises
    NotConnected (a LinkError) and stays closed until the controller reopens it."""
    ctl, client = rig.controller, rig.device.client
    connects = client.connects
    if rig.device.settings.transport == 'tcp':
        rig.sim.drop_link()
    else:
        rig.sim.pty.drop_link(offline_for=0.2)
    with pytest.raises(NotConnected) as info:
        for _ in range(200):
            client.read_axis(1)
    assert isinstance(info.value, LinkError)
    wait_for(lambda: ctl.reconnects >= 1 and ctl.connected, 15.0, 'reconnected')
    assert client.connected and client.connects >= connects + 1
    assert client.read_axis(2)[0] == 0.0
    targets = rig.motion.start_move(['tilt'], [0.1])
    assert rig.motion.wait_move(targets).success


def test_levelling_targets_and_reaches_the_leveling_value(tcp_rig):
    ctl, device = tcp_rig.controller, tcp_rig.device
    tcp_rig.sim.model.set_pose(2, 10.0)
    tcp_rig.wait_positions({'tilt': math.radians(10.0)})
    ctl.call(lambda: device.functions.command('IMU_setLevelingValue', 2, ['-3']))
    ctl.call(lambda: device.functions.start_leveling(['tilt']))
    # the end pose is reported (and was limit-checked) in rad, REP-103
    assert ctl.commanded_targets['tilt'] == pytest.approx(math.radians(-3.0), abs=1e-3)
    wait_for(lambda: ctl.call(lambda: device.functions.level_errors(['tilt'])).within(2e-3)
             and not ctl.moving('tilt'), 20.0, 'levelled')
    assert tcp_rig.sim_axis(2).position == pytest.approx(-3.0, abs=0.1)
    with pytest.raises(InvalidRequest, match='unknown joint'):
        ctl.call(lambda: device.functions.start_leveling(['elbow']))


@contextlib.contextmanager
def a_posted_move(rig: Rig, joint: str, targets: Sequence[float],
                  arm: Callable[[], None] = lambda: None) -> Iterator[float]:
    """Hold the link lock and command ``joint`` to the next of ``targets`` until one is
    posted (written at once from this thread); yields its target with the lock still held.
    The poll's reads overlap setters, and a post gives way to the command thread while a
    read the device may answer with a byte is in flight: that command then goes out as a
    full move once the lock is released, and the next target is tried. ``arm`` runs under
    the lock before each command; an attempt that was not posted clears what it injected."""
    def posted() -> int:
        return rig.device.client.stats['posted_moves']  # a copy each time

    for target in targets:
        with rig.device.link_lock:
            before = posted()
            arm()
            rig.controller.command([joint], [target], [])
            if posted() == before + 1:
                yield target
                return
            rig.sim.model.clear_injected()
        rig.wait_positions({joint: target})
    raise AssertionError(f'no move of {joint} to {list(targets)} was posted')


def test_a_posted_stream_move_is_settled_through_the_link_lock_and_a_stop_wins(tcp_rig):
    """A stream move goes out from the caller's thread (posted, one write) once the axis
    is set up; the device's one link lock settles its ACKs before the next exchange. With
    an ACK lost and a stop sent before it settles, the stale move is not sent again."""
    ctl, sim = tcp_rig.controller, tcp_rig.sim
    ctl.command(['pan'], [0.05], [])  # the first move sets the axis up (command thread)
    tcp_rig.wait_positions({'pan': 0.05})
    # the command thread waits for the lock: nothing settles the post meanwhile
    with a_posted_move(tcp_rig, 'pan', [0.1, 0.11, 0.12, 0.13, 0.14]) as target:
        pass
    tcp_rig.wait_positions({'pan': target})
    assert ctl.rejections.counts()['refused'] == {}
    sent_before: list[int] = []  # MOT_SendPosition at the simulator before each attempt

    def lose_the_next_reply() -> None:
        sim.model.lose_replies(1)
        sent_before.append(tcp_rig.sent('MOT_SendPosition'))

    with a_posted_move(tcp_rig, 'pan', [1.5, 1.49, 1.48, 1.47, 1.46],
                       arm=lose_the_next_reply) as far:
        # the posted write is on its way: counted once the simulator has taken it
        wait_for(lambda: tcp_rig.sent('MOT_SendPosition') == sent_before[-1] + 1, 10.0,
                 'the posted move at the simulator')
        sends = tcp_rig.sent('MOT_SendPosition')
        ctl.stop()  # settles the post first (an ACK lost), then stops: no resend
    wait_for(lambda: sim.model.axes[1].velocity == 0.0, 10.0, 'pan stopped')
    assert tcp_rig.sent('MOT_SendPosition') == sends  # the lost move was not sent again
    assert 'pan' not in ctl.commanded_targets or ctl.commanded_targets['pan'] != far


def test_a_move_to_drops_the_joint_commands_queued_behind_a_busy_link(tcp_rig):
    """Issue 39 item 4, over TCP: a pan move and a tilt jog wait behind an exchange in
    flight; a move_to given meanwhile supersedes both, so neither reaches the pedestal."""
    ctl, motion = tcp_rig.controller, tcp_rig.motion
    tilt_before = tcp_rig.sim_axis(2).position
    speed_modes = tcp_rig.sent('MOT_SetSpeedMode')
    taken, release = threading.Event(), threading.Event()

    def hold_link() -> None:  # a read waiting for its answer
        with tcp_rig.device.link_lock:
            taken.set()
            release.wait(10.0)

    holder = threading.Thread(target=hold_link, daemon=True)
    holder.start()
    assert taken.wait(5.0)
    try:
        ctl.command(['pan'], [0.5], [])
        ctl.command(['tilt'], [], [0.3])
        generation = ctl.motion_generation
        mover = threading.Thread(target=motion.start_move, args=(['pan'], [-0.2]),
                                 daemon=True)
        mover.start()
        wait_for(lambda: ctl.motion_generation != generation, 5.0, 'the move_to to preempt')
    finally:
        release.set()
    holder.join(5.0)
    mover.join(10.0)
    tcp_rig.wait_positions({'pan': -0.2})
    assert tcp_rig.sent('MOT_SetSpeedMode') == speed_modes  # the tilt jog never went out
    assert tcp_rig.sim_axis(2).velocity == 0.0
    assert tcp_rig.sim_axis(2).position == pytest.approx(tilt_before, abs=1e-6)
    assert ctl.commanded_targets.get('pan') == pytest.approx(-0.2)


def test_a_stop_goes_out_while_a_sensor_read_waits_for_an_answer_that_never_comes(tcp_rig):
    """Issue 39 items 1 and 2, over TCP: with IMU_GetRoll muted in the simulator and an IMU
    read waiting for it, ~/stop reaches the pedestal and is answered while that read still
    waits, and the joint poll goes on beside it."""
    ctl, sim = tcp_rig.controller, tcp_rig.sim
    client = tcp_rig.device.client
    client.timeout = 5.0  # a long wait for the muted getter: the stop comes well inside it
    sim.model.request_faults.mute('IMU_GetRoll')
    asked = tcp_rig.sent('IMU_GetRoll')
    reader = threading.Thread(target=client.optional, args=('IMU_GetRoll',), daemon=True)
    reader.start()
    wait_for(lambda: tcp_rig.sent('IMU_GetRoll') == asked + 1, 5.0, 'the IMU read sent')
    polls = tcp_rig.sent('MOT_GetLoadPosition')
    wait_for(lambda: tcp_rig.sent('MOT_GetLoadPosition') >= polls + 4, 5.0,
             'the joint poll going on beside the waiting read')
    stops = tcp_rig.sent('SCN_StopScan')
    assert ctl.stop().startswith('all axes stopped')
    assert tcp_rig.sent('SCN_StopScan') > stops
    assert reader.is_alive()  # the read still waits for its answer
    sim.model.request_faults.clear()
    reader.join(10.0)


def test_a_register_that_never_answers_holds_up_neither_the_poll_nor_a_jog(tcp_rig):
    """Issue 39 item 1, over TCP: the registers are read on the sensors thread and a read
    waits for its own answer, so with ERR_OperationRegister muted (and a long timeout, so
    the read is still waiting throughout) joint samples keep coming and a jog goes out."""
    ctl, sim = tcp_rig.controller, tcp_rig.sim
    device = tcp_rig.device
    wait_for(lambda: device.status_snapshot(), 10.0, 'a first register poll')
    device.client.timeout = 5.0
    sim.model.request_faults.mute('ERR_OperationRegister')
    asked = tcp_rig.sent('ERR_OperationRegister')
    device.expire_status()
    wait_for(lambda: tcp_rig.sent('ERR_OperationRegister') > asked, 5.0, 'the muted read sent')
    polls = tcp_rig.sent('MOT_GetLoadPosition')
    wait_for(lambda: tcp_rig.sent('MOT_GetLoadPosition') >= polls + 6, 5.0,
             'joint polls while the register read waits')
    ctl.command(['pan'], [], [0.3])
    wait_for(lambda: tcp_rig.sim_axis(1).velocity != 0.0, 5.0, 'the jog on the axis')
    assert 'ERR_OperationRegister' in device.client.answers.in_flight()  # still waiting
    ctl.stop()
    sim.model.request_faults.clear()


def test_registers_are_read_at_open_and_at_once_after_expire_status(sim):
    """The sensors thread sleeps for status_period between register reads (no tick that
    looks whether they are due): with an hour's period they are still read when the link
    opens, and at once after a command that changes them (``expire_status``)."""
    device = CaptureDevice(make_settings(sim, status_period=3600.0))
    ctl = GimbalController(device, make_config(), LOG)
    ctl.open()
    ctl.activate()
    try:
        wait_for(lambda: device.status_snapshot(), 10.0, 'the registers read at open')
        assert ctl.refusal(['pan']) is None
        sim.model.inject_fault(1, 'over_current')
        device.expire_status()
        wait_for(lambda: ctl.refusal(['pan']) is not None, 10.0, 'the fault read at once')
    finally:
        ctl.shutdown()
