"""KosDevice under the shared GimbalController, against the kOS simulator over TCP loopback.

No ROS: the controller (link supervision, command thread, jog watchdog) and the policies run
in this process around the adapter, the simulator answers over a real socket and records
every motion command it receives (its receive side, in rotations).

Units (issue 22): pan and tilt have calibrated spans on the simulator's calibrated ranges
(pan 0..100 rotations = -pi..pi rad, tilt 0..-40 rotations = -pi/2..+pi/2 rad: the tilt
motor counts down as the joint rises, so every test also crosses the sign flip); the slider
has no span and reports motor radians (joint_scales 2*pi, offset 0) over 0..200 rotations.
"""

from __future__ import annotations

import logging
import math
import threading

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.diagnostics import Level
from gimbal_driver_common.errors import DeviceRefused, GimbalError, InvalidRequest, LinkError
from gimbal_driver_common.errors import DeviceTimeout as CoreDeviceTimeout
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.policies import HomingSuperseded, Motion
from gimbal_driver_testing import wait_for
from kessler_kos_driver.client import (
    CommandRejected,
    DeviceTimeout,
    KosClient,
    NotConnected,
    PasswordRejected,
)
from kessler_kos_driver.device import KosDevice, KosSettings, joint_mappings
from kessler_kos_driver.moves import Keyframe, PlaybackSettings
from kessler_kos_driver.protocol import PlaybackState, SetPositionSpeedAcceleration
from kessler_kos_driver.sim import KosSimulator, SimSettings
from kessler_kos_driver.units import MOTOR_RADIANS, JointUnits

PASSWORD = 'dev-secret'
TWO_PI = 2 * math.pi
JOINTS = ['slider', 'pan', 'tilt']
UNITS = [JointUnits(),                                     # slider: no span, motor radians
         JointUnits(span=TWO_PI, offset=-math.pi),         # pan: -pi..pi over 0..100 rot
         JointUnits(span=math.pi, offset=-math.pi / 2)]    # tilt: -pi/2..pi/2 over 0..-40
ADDRESS = {'slider': 1, 'pan': 2, 'tilt': 3}
PAN_RAD_PER_ROT = TWO_PI / 100.0
TILT_RAD_PER_ROT = math.pi / -40.0
TIMEOUT = 30.0
LOG = logging.getLogger('test_device')


class Rig:
    """Simulator (with its receive side recorded), client, adapter and controller."""

    def __init__(self, command_timeout: float = 0.3) -> None:
        self.sim = KosSimulator(SimSettings(password=PASSWORD, precalibrated=True,
                                            time_scale=10.0), port=0, discovery_port=0)
        self.received: list[SetPositionSpeedAcceleration] = []
        handle = self.sim.device.handle

        def recorded(message, frame, session):
            if isinstance(message, SetPositionSpeedAcceleration):
                self.received.append(message)
            return handle(message, frame, session)

        self.sim.device.handle = recorded
        self.sim.start()
        self.client = KosClient('127.0.0.1', self.sim.port, password=PASSWORD,
                                poll_period=0.02, reply_timeout=2.0)
        limits = {n: JointLimits(-1000.0, 1000.0, 60.0) for n in JOINTS}
        self.config = ControllerConfig(
            JOINTS, limits, publish_rate=50.0, command_timeout=command_timeout,
            reconnect_period=0.05, goal_tolerance=0.011, move_timeout=TIMEOUT)
        self.playback: list = []
        self.device = KosDevice(self.client, joint_mappings(JOINTS, [1, 2, 3], UNITS),
                                self.config, KosSettings(playback_timeout=TIMEOUT),
                                on_playback=self.playback.append)
        self.link_states: list[bool] = []
        self.link_errors: list[str] = []
        self.controller = GimbalController(self.device, self.config, LOG,
                                           on_link_change=self._link_changed)
        self.motion = Motion(self.controller, scan_patterns=('sector',))

    def _link_changed(self) -> None:
        self.link_states.append(self.controller.connected)
        self.link_errors.append(self.controller.link_error)

    def start(self) -> Rig:
        self.controller.open()
        self.controller.activate()
        wait_for(lambda: len(self.controller.positions()) == 3, TIMEOUT, 'first joint sample')
        return self

    def motor(self, joint: str):
        return self.sim.device.motors[ADDRESS[joint]]

    def motor_position(self, joint: str) -> float:
        with self.sim.device.lock:
            return self.motor(joint).position

    def motor_commands(self) -> dict[str, tuple[float, float, bool]]:
        """(target, speed, moving) of every motor: what the last motion command set."""
        with self.sim.device.lock:
            return {j: (self.motor(j).target, self.motor(j).speed, self.motor(j).moving)
                    for j in ADDRESS}

    def motor_moving(self, joint: str) -> bool:
        with self.sim.device.lock:
            return self.motor(joint).moving

    def received_for(self, joint: str) -> list[SetPositionSpeedAcceleration]:
        """The motion commands the simulator received for the joint's motor."""
        return [m for m in list(self.received) if m.motor_address == ADDRESS[joint]]

    def position_reads(self, joint: str, value: float, tolerance: float = 1e-3) -> bool:
        return abs(self.controller.positions()[joint] - value) < tolerance

    def axis_diagnostics(self, joint: str):
        part = next(p for p in self.device.status.parts() if p.part == joint)
        return part, dict(part.values)

    def close(self) -> None:
        self.controller.shutdown()
        self.sim.stop()


@pytest.fixture
def rig():
    rig = Rig().start()
    yield rig
    rig.close()


def test_connect_and_identity(rig):
    ctl = rig.controller
    assert ctl.connected and ctl.link_error == ''
    info = ctl.device_info
    assert info.model == 'Kessler CineShooter'
    assert info.serial_number == rig.client.guid != ''
    assert info.hardware_id == rig.client.guid
    assert info.firmware_version == rig.client.device_info.firmware
    assert rig.device.description() == f'tcp://127.0.0.1:{rig.sim.port}'
    assert rig.device.streamed and rig.device.capabilities.presets is None
    assert rig.device.capabilities.scans is None   # the driver-side sector scan serves kOS


def test_a_sample_is_stamped_with_its_oldest_motor_report():
    """Positions arrive at different times (the MotorInfo poll for every motor, a
    MotorPosition notification for one): the one JointState stamp must not make an older
    position look current."""
    sim = KosSimulator(SimSettings(password=PASSWORD, precalibrated=True), port=0,
                       discovery_port=0)
    sim.start()
    client = KosClient('127.0.0.1', sim.port, password=PASSWORD, poll_period=60.0,
                       reply_timeout=2.0)
    limits = {n: JointLimits(-1000.0, 1000.0, 60.0) for n in JOINTS}
    device = KosDevice(client, joint_mappings(JOINTS, [1, 2, 3], UNITS),
                       ControllerConfig(JOINTS, limits))
    try:
        device.open()
        polled = device.read().stamp   # one MotorInfo: every motor reported at once
        assert {m.stamp for m in client.motors.values()} == {polled}
        client.motors[ADDRESS['slider']].stamp = polled + 0.02  # a newer report of one
        assert device.read().stamp == polled
    finally:
        device.close()
        sim.stop()


def test_client_errors_are_in_the_shared_hierarchy():
    assert issubclass(NotConnected, LinkError)
    assert issubclass(DeviceTimeout, CoreDeviceTimeout)
    assert issubclass(CommandRejected, DeviceRefused)
    assert issubclass(PasswordRejected, DeviceRefused)


def test_wrong_password_fails_open_as_a_refusal():
    sim = KosSimulator(SimSettings(password=PASSWORD), port=0, discovery_port=0).start()
    try:
        client = KosClient('127.0.0.1', sim.port, password='wrong', poll_period=0)
        config = ControllerConfig(JOINTS, {n: JointLimits() for n in JOINTS})
        ctl = GimbalController(KosDevice(client, joint_mappings(JOINTS, [1, 2, 3], UNITS),
                                         config), config, LOG)
        with pytest.raises(DeviceRefused, match='password'):
            ctl.open()
        assert not ctl.connected and 'password' in ctl.link_error
        assert 'wrong' not in ctl.link_error
    finally:
        sim.stop()


def test_calibrated_axes_report_si_and_an_axis_without_a_span_motor_radians(rig):
    """Motors moved on the device directly (rotations) read back in SI: pan and tilt by
    offset + rotations * span / end, the slider (no span) as motor radians."""
    # every motor starts at its begin mark: the offsets
    assert rig.controller.positions() == pytest.approx(
        {'slider': 0.0, 'pan': -math.pi, 'tilt': -math.pi / 2}, abs=1e-6)
    rig.client.commands.move_to(ADDRESS['pan'], 75.0, 50.0)       # 3/4 of the range: +pi/2
    rig.client.commands.move_to(ADDRESS['tilt'], -10.0, 20.0)     # 1/4 of 0..-40: -pi/4
    rig.client.commands.move_to(ADDRESS['slider'], 2.0, 50.0)     # two motor turns: 4 pi
    wait_for(lambda: rig.position_reads('pan', math.pi / 2)
             and rig.position_reads('tilt', -math.pi / 4)
             and rig.position_reads('slider', 4 * math.pi), TIMEOUT, 'the SI positions')
    assert rig.device.units_report() == {'slider': MOTOR_RADIANS,
                                         'pan': 'SI (calibrated_spans)',
                                         'tilt': 'SI (calibrated_spans)'}
    slider, values = rig.axis_diagnostics('slider')
    assert slider.level == Level.OK and values['units'] == 'motor radians'
    assert float(values['si_per_rotation']) == pytest.approx(TWO_PI, abs=1e-5)
    pan, values = rig.axis_diagnostics('pan')
    assert pan.level == Level.OK and values['units'] == 'SI (calibrated_spans)'
    assert float(values['begin_position']) == pytest.approx(-math.pi, abs=1e-5)
    assert float(values['end_position']) == pytest.approx(math.pi, abs=1e-5)
    assert float(values['max_setup_speed']) == pytest.approx(165.0 * PAN_RAD_PER_ROT, abs=1e-4)
    _, values = rig.axis_diagnostics('tilt')
    assert float(values['si_per_rotation']) == pytest.approx(TILT_RAD_PER_ROT, abs=1e-6)
    assert float(values['end_position']) == pytest.approx(math.pi / 2, abs=1e-5)


def test_an_si_move_lands_on_the_right_rotations_on_the_receive_side(rig):
    samples = []
    rig.controller.on_sample = samples.append
    targets = rig.motion.start_move(['pan', 'tilt', 'slider'], [math.pi / 2, 0.25, 3.0],
                                    [1.0, 0.5, 5.0])   # slow enough to sample the velocity
    outcome = rig.motion.wait_move(targets)
    assert outcome.success, outcome.message
    # what the device received, in rotations (Float32 on the wire)
    expected = {'pan': 75.0,                                   # (pi/2 + pi) * 100 / 2pi
                'tilt': (0.25 + math.pi / 2) * -40.0 / math.pi,  # -23.18: counts down
                'slider': 3.0 / TWO_PI}                        # motor radians
    for joint, rotations in expected.items():
        assert rig.received_for(joint)[-1].position == pytest.approx(rotations, abs=1e-4)
        assert rig.motor_position(joint) == pytest.approx(rotations, abs=1e-3)
    # the tilt rose in SI while its motor turned negative
    assert any(s.velocities.get('tilt', 0.0) > 0.1 for s in samples)
    assert not any(s.velocities.get('tilt', 0.0) < -0.1 for s in samples)
    assert rig.controller.commanded_targets == {'pan': math.pi / 2, 'tilt': 0.25, 'slider': 3.0}


def test_move_speed_converts_to_rotations_per_second(rig):
    rig.device.move({'pan': (2.0, 5 * PAN_RAD_PER_ROT)})    # 5 rot/s
    wait_for(lambda: rig.motor_moving('pan'), TIMEOUT, 'pan moving')
    sent = rig.received_for('pan')[-1]
    assert sent.speed == pytest.approx(5.0)
    assert sent.position == pytest.approx((2.0 + math.pi) / PAN_RAD_PER_ROT, abs=1e-4)
    with rig.sim.device.lock:
        motor = rig.motor('pan')
        assert motor.speed == pytest.approx(5.0)
        assert motor.acceleration == pytest.approx(motor.max_acceleration * 0.5)


def test_jog_is_stopped_by_the_watchdog(rig):
    ctl = rig.controller
    rig.motion.wait_move(rig.motion.start_move(['tilt'], [-1.0]))
    start = rig.motor_position('tilt')
    ctl.command(['tilt'], [], [0.5])       # +0.5 rad/s: the motor turns toward negative
    wait_for(lambda: rig.motor_moving('tilt'), TIMEOUT, 'tilt jogging')
    assert ctl.watchdog.jogging == ['tilt']
    assert rig.received_for('tilt')[-1].speed == pytest.approx(0.5 / -TILT_RAD_PER_ROT)
    # nothing feeds the jog: the watchdog stops it after command_timeout
    wait_for(lambda: not ctl.watchdog.jogging, TIMEOUT, 'the jog watchdog to expire')
    wait_for(lambda: not rig.motor_moving('tilt'), TIMEOUT, 'tilt stopped')
    stopped_at = rig.motor_position('tilt')
    assert -40.0 < stopped_at < start       # moved the SI-positive way, short of the end
    assert ctl.positions()['tilt'] > -1.0


def test_stop_halts_a_move(rig):
    ctl = rig.controller
    rig.motion.start_move(['slider'], [900.0], [30.0])      # motor radians: 143 rotations
    wait_for(lambda: rig.motor_moving('slider'), TIMEOUT, 'slider moving')
    assert 'stopped' in ctl.stop()
    wait_for(lambda: not rig.motor_moving('slider'), TIMEOUT, 'slider stopped')
    assert rig.motor_position('slider') < 900.0 / TWO_PI - 1.0


@pytest.mark.parametrize('joints', [None, ['slider', 'pan', 'tilt']])
def test_a_stop_writes_every_motor_whatever_one_write_does(rig, monkeypatch, joints):
    commands = rig.client.commands
    real, sent = commands.send, []

    def send(message):
        sent.append(type(message).__name__)
        if len(sent) == 1:
            raise OSError('write failed')  # the first motor's stop does not go out
        real(message)

    monkeypatch.setattr(commands, 'send', send)
    with pytest.raises(GimbalError, match='write failed'):
        rig.device.stop(joints)
    # every other motor's stop still went out, device motion before the program's stop
    expected = ['SetPositionSpeedAcceleration'] * 3 + (['StopPlayback'] if joints is None
                                                       else [])
    assert sent == expected


def test_refusal_reasons_in_si_and_nothing_sent(rig):
    ctl = rig.controller
    before, received = rig.motor_commands(), len(rig.received)
    # outside the calibrated tilt range (-pi/2..pi/2 here): the device limit, before sending
    with pytest.raises(InvalidRequest, match=r"joint 'tilt': -2.0000 is outside the "
                                             r'calibrated range \[-1.5708, 1.5708\]'):
        rig.motion.start_move(['tilt'], [-2.0])
    with pytest.raises(InvalidRequest, match=r"joint 'pan': speed 11.0000 exceeds the motor "
                                             r'maximum 10.3673 \(MaxMaxSetupSpeed'):
        rig.device.move({'pan': (1.0, 11.0)})
    with pytest.raises(InvalidRequest, match=r"joint 'pan'.*exceeds the motor maximum"):
        rig.device.jog({'pan': -11.0})
    with pytest.raises(InvalidRequest, match=r"joint 'slider'.*calibrated range \[0.0000, "
                                             r'1256.6371\] \(motor radians'):
        rig.device.move({'slider': (-1.0, None)})
    assert rig.motor_commands() == before     # no motion command reached the device
    assert len(rig.received) == received
    assert rig.sim.command('offline 2') == 'ok'
    wait_for(lambda: ctl.refusal(['pan']), TIMEOUT, 'pan offline')
    assert ctl.refusal(['pan']) == "joint 'pan': motor 2 is offline"
    with pytest.raises(DeviceRefused, match='offline'):
        rig.motion.start_move(['pan'], [1.0])
    assert rig.sim.command('online 2') == 'ok'
    wait_for(lambda: ctl.refusal(['pan']) is None, TIMEOUT, 'pan online')
    with pytest.raises(InvalidRequest, match='unknown joint'):
        rig.motion.start_move(['elbow'], [0.0])
    ctl.deactivate()
    assert 'not active' in ctl.refusal()
    ctl.activate()


def test_keyframe_playback_in_si(rig):
    frames = [Keyframe(0.0, {'pan': -1.0, 'tilt': -0.5}),
              Keyframe(2.0, {'pan': 1.0, 'tilt': 0.5})]
    trajectory = rig.device.playback.load_keyframes(frames, PlaybackSettings())
    # normalised on the device: pan (SI + pi) / 2pi, tilt (SI + pi/2) / pi
    pan = trajectory.axes[ADDRESS['pan']]
    tilt = trajectory.axes[ADDRESS['tilt']]
    assert pan[0].p0_position == pytest.approx((-1.0 + math.pi) / TWO_PI, abs=1e-6)
    assert pan[-1].p3_position == pytest.approx((1.0 + math.pi) / TWO_PI, abs=1e-6)
    assert tilt[-1].p3_position == pytest.approx((0.5 + math.pi / 2) / math.pi, abs=1e-6)
    rig.device.playback.setup_playback(delay_return=False)
    rig.device.playback.start_playback()
    wait_for(lambda: PlaybackState.FULL_STOP in rig.client.playback.history, TIMEOUT,
             'FullStop')
    report = next(r for r in rig.playback if r.status == PlaybackState.FULL_STOP)
    assert report.positions == pytest.approx({'pan': 1.0, 'tilt': 0.5}, abs=1e-4)
    assert rig.motor_position('pan') == pytest.approx((1.0 + math.pi) / PAN_RAD_PER_ROT,
                                                      abs=1e-3)
    assert rig.motor_position('tilt') == pytest.approx(
        (0.5 + math.pi / 2) / TILT_RAD_PER_ROT, abs=1e-3)
    wait_for(lambda: rig.position_reads('pan', 1.0) and rig.position_reads('tilt', 0.5),
             TIMEOUT, 'joint positions at the last key frame')
    # outside the calibrated range in SI: refused with the SI range, nothing loaded
    with pytest.raises(DeviceRefused, match=r"'tilt'.*calibrated range \[-1.5708, 1.5708\]"):
        rig.device.playback.load_keyframes(
            [Keyframe(0.0, {'tilt': 0.0}), Keyframe(1.0, {'tilt': 1.6})], PlaybackSettings())
    assert not rig.client.playback.loaded    # FullStop consumed the move; nothing new sent


def test_a_recalibration_changes_the_conversion(rig, caplog):
    """A new end mark: the pan's span (-pi..pi) now lies over the new range, at once."""
    outcome = rig.motion.wait_move(rig.motion.start_move(['pan'], [-2.0]))
    assert outcome.success, outcome.message
    rig.device.functions.mark_begin('pan')
    begin = rig.motor_position('pan')
    rig.client.commands.move_to(ADDRESS['pan'], begin + 50.0, 50.0)  # on the device, in rotations
    wait_for(lambda: abs(rig.motor_position('pan') - (begin + 50.0)) < 1e-3, TIMEOUT,
             'pan 50 rotations on')
    with caplog.at_level(logging.INFO, logger='kessler_kos_driver.device'):
        assert rig.device.functions.mark_end('pan') == pytest.approx((-math.pi, math.pi), abs=1e-5)
    assert "joint 'pan': end mark now 50 rotations (was 100)" in caplog.text
    # the device says: begin 0, end 50, position 50 = the end mark = +pi
    wait_for(lambda: rig.position_reads('pan', math.pi), TIMEOUT, 'pan at +pi')
    _, values = rig.axis_diagnostics('pan')
    assert float(values['end_position_rotations']) == pytest.approx(50.0)
    # commands follow the new span: 0 rad is now 25 rotations (was 50)
    outcome = rig.motion.wait_move(rig.motion.start_move(['pan'], [0.0]))
    assert outcome.success, outcome.message
    assert rig.received_for('pan')[-1].position == pytest.approx(25.0, abs=1e-4)
    assert rig.motor_position('pan') == pytest.approx(25.0, abs=1e-3)


def test_new_units_keep_the_motor_positions_of_the_commanded_targets(rig):
    outcome = rig.motion.wait_move(rig.motion.start_move(['pan', 'slider'], [0.0, 3.0]))
    assert outcome.success, outcome.message
    targets = dict(rig.controller.commanded_targets)
    # pan: a quarter turn offset; slider: a 0.01 m per rotation belt instead of motor radians
    rig.device.set_units([JointUnits(scale=0.01), JointUnits(span=TWO_PI, offset=-math.pi / 2),
                          UNITS[2]], targets)  # reported to the controller, not written
    assert rig.controller.commanded_targets == pytest.approx(
        {'pan': math.pi / 2, 'slider': 0.03 / TWO_PI})
    wait_for(lambda: rig.position_reads('pan', math.pi / 2)
             and rig.position_reads('slider', 0.03 / TWO_PI, 1e-6), TIMEOUT, 'the new units')
    assert rig.device.units_report()['slider'] == 'SI (joint_scales)'


def test_playback_owns_the_motors(rig):
    ctl = rig.controller
    frames = [Keyframe(0.0, {'pan': -2.0, 'tilt': 0.2}),
              Keyframe(4.0, {'pan': 2.0, 'tilt': 1.0})]
    rig.device.playback.load_keyframes(frames, PlaybackSettings(loop_count=255, rapid_reverse=True))
    rig.device.playback.start_playback()
    wait_for(lambda: rig.client.playback_running, TIMEOUT, 'playback running')
    assert 'a move is playing' in ctl.refusal(['pan'])
    with pytest.raises(DeviceRefused, match='a move is playing'):
        rig.device.move({'pan': (1.0, None)})
    wait_for(lambda: ctl.latest and all(ctl.latest.moving.values()), TIMEOUT, 'moving bits')
    ctl.stop()
    wait_for(lambda: PlaybackState.FULL_STOP in rig.client.playback.history, TIMEOUT,
             'FullStop')
    report = next(r for r in rig.playback if r.status == PlaybackState.FULL_STOP)
    assert set(report.positions) == {'pan', 'tilt'} and report.positions['tilt'] > 0.0


def test_home_moves_calibrated_joints_to_their_begin_mark(rig):
    outcome = rig.motion.wait_move(rig.motion.start_move(['pan', 'tilt'], [1.5, 0.5]))
    assert outcome.success, outcome.message
    message = rig.motion.home(['pan', 'tilt'], lambda state: None)
    assert message == "at the begin mark: ['pan', 'tilt']"
    # done within goal_tolerance (SI); the device was sent the begin marks, 0 rotations
    assert [m.position for m in rig.received[-2:]] == [0.0, 0.0]
    wait_for(lambda: abs(rig.motor_position('pan')) < 1e-3
             and abs(rig.motor_position('tilt')) < 1e-3, TIMEOUT, 'the motors at 0 rotations')
    wait_for(lambda: rig.position_reads('pan', -math.pi)      # the begin marks: the offsets
             and rig.position_reads('tilt', -math.pi / 2), TIMEOUT, 'the begin marks in SI')


@pytest.mark.parametrize('end', ['cancel', 'stop'])
def test_a_homing_on_its_way_ends_at_a_cancel_request_or_a_stop(rig, end):
    """kOS homing reports once and then waits for the begin marks: a cancel request or a
    ~/stop must end that wait at once (it used to run on until move_timeout)."""
    outcome = rig.motion.wait_move(rig.motion.start_move(['pan'], [2.0]))
    assert outcome.success, outcome.message
    with rig.sim.device.lock:
        rig.sim.device.settings.time_scale = 0.2  # a homing move that lasts
    states, requested, ended = [], threading.Event(), {}

    def run() -> None:
        try:
            ended['answer'] = rig.motion.home(['pan'], states.append, requested.is_set)
        except GimbalError as exc:
            ended['error'] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    wait_for(lambda: rig.controller.positions()['pan'] < 1.9, TIMEOUT,
             'the homing move to start')
    if end == 'cancel':
        requested.set()
    else:
        rig.controller.stop()
    thread.join(TIMEOUT)
    assert not thread.is_alive()
    if end == 'cancel':
        assert str(ended['error']) == 'homing cancelled'
        rig.controller.stop_joints(['pan'])  # what the action does on a cancel
    else:
        assert isinstance(ended['error'], HomingSuperseded)
    wait_for(lambda: not rig.controller.moving('pan'), TIMEOUT, 'pan to stop')
    assert rig.controller.positions()['pan'] > -math.pi + 0.1  # short of the begin mark


def test_link_drop_then_reconnect(rig):
    ctl = rig.controller
    rig.sim.command('drop 0.3')
    wait_for(lambda: False in rig.link_states, TIMEOUT, 'link lost')
    wait_for(lambda: ctl.connected and ctl.reconnects >= 1, TIMEOUT, 'reconnected')
    assert rig.link_states[-1] is True
    rig.client.refresh_motors()
    outcome = rig.motion.wait_move(rig.motion.start_move(['pan'], [3.0]))
    assert outcome.success, outcome.message


def test_silent_device_is_detected_and_recovered(rig):
    ctl = rig.controller
    rig.client.silence_timeout = 0.5
    rig.sim.server.set_silent(True)
    wait_for(lambda: False in rig.link_states, TIMEOUT, 'the silent link to be dropped')
    assert 'silent' in rig.link_errors[rig.link_states.index(False)]
    rig.sim.server.set_silent(False)
    wait_for(lambda: ctl.connected, TIMEOUT, 'reconnected')
