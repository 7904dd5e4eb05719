"""KosDevice under the shared GimbalController, against the kOS simulator over TCP loopback.

No ROS: the controller (link supervision, command thread, jog watchdog) and the policies run
in this process around the adapter, the simulator answers over a real socket. The tilt joint
has a negative scale (-2*pi rad per rotation) so every test also crosses the sign flip; the
simulator's calibrated tilt range is 0..-40 rotations, i.e. 0..+251 rad here.
"""

from __future__ import annotations

import logging
import math
import threading

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.errors import DeviceRefused, GimbalError, InvalidRequest, LinkError
from gimbal_driver_common.errors import DeviceTimeout as CoreDeviceTimeout
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.policies import HomingSuperseded, Motion
from gimbal_driver_common.testing import wait_for
from kessler_kos_driver.client import (
    CommandRejected,
    DeviceTimeout,
    KosClient,
    NotConnected,
    PasswordRejected,
)
from kessler_kos_driver.device import KosDevice, KosSettings, joint_mappings
from kessler_kos_driver.moves import Keyframe, PlaybackSettings
from kessler_kos_driver.protocol import PlaybackState
from kessler_kos_driver.sim import KosSimulator, SimSettings

PASSWORD = 'dev-secret'
TWO_PI = 2 * math.pi
JOINTS = ['slider', 'pan', 'tilt']
SCALES = [TWO_PI, TWO_PI, -TWO_PI]      # tilt counts the other way
ADDRESS = {'slider': 1, 'pan': 2, 'tilt': 3}
TIMEOUT = 30.0
LOG = logging.getLogger('test_device')


class Rig:
    """Simulator, client, adapter and controller."""

    def __init__(self, command_timeout: float = 0.3) -> None:
        self.sim = KosSimulator(SimSettings(password=PASSWORD, precalibrated=True,
                                            time_scale=10.0), port=0, discovery_port=0)
        self.sim.start()
        self.client = KosClient('127.0.0.1', self.sim.port, password=PASSWORD,
                                poll_period=0.02, reply_timeout=2.0)
        limits = {n: JointLimits(-1000.0, 1000.0, 60.0) for n in JOINTS}
        self.config = ControllerConfig(
            JOINTS, limits, publish_rate=50.0, command_timeout=command_timeout,
            reconnect_period=0.05, goal_tolerance=0.011, move_timeout=TIMEOUT)
        self.playback: list = []
        self.device = KosDevice(self.client, joint_mappings(JOINTS, [1, 2, 3], SCALES),
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
        ctl = GimbalController(KosDevice(client, joint_mappings(JOINTS, [1, 2, 3], SCALES),
                                         config), config, LOG)
        with pytest.raises(DeviceRefused, match='password'):
            ctl.open()
        assert not ctl.connected and 'password' in ctl.link_error
        assert 'wrong' not in ctl.link_error
    finally:
        sim.stop()


def test_move_converges_with_units_and_signs_both_ways(rig):
    samples = []
    rig.controller.on_sample = samples.append
    targets = rig.motion.start_move(['pan', 'tilt'], [20.0, 20.0])
    outcome = rig.motion.wait_move(targets)
    assert outcome.success, outcome.message
    # SI -> rotations: pan +20 rad is +20/2pi rot, tilt +20 rad is -20/2pi rot (scale < 0)
    assert rig.motor_position('pan') == pytest.approx(20.0 / TWO_PI, abs=1e-3)
    assert rig.motor_position('tilt') == pytest.approx(-20.0 / TWO_PI, abs=1e-3)
    # ... and the tilt velocity read while it moved is positive in SI (motor turned negative)
    assert any(s.velocities.get('tilt', 0.0) > 0.1 for s in samples)
    assert not any(s.velocities.get('tilt', 0.0) < -0.1 for s in samples)
    assert rig.controller.commanded_targets == {'pan': 20.0, 'tilt': 20.0}
    # rotations -> SI: a move made on the device directly reads back scaled and flipped
    rig.client.move_to(ADDRESS['tilt'], -5.0, 5.0)
    wait_for(lambda: abs(rig.controller.positions()['tilt'] - 5.0 * TWO_PI) < 1e-3,
             TIMEOUT, 'tilt at +5 turns in SI')


def test_move_speed_converts_to_rotations_per_second(rig):
    rig.device.move({'pan': (30.0, TWO_PI)})    # 1 rot/s
    wait_for(lambda: rig.motor_moving('pan'), TIMEOUT, 'pan moving')
    with rig.sim.device.lock:
        motor = rig.motor('pan')
        assert motor.speed == pytest.approx(1.0)
        assert motor.acceleration == pytest.approx(motor.max_acceleration * 0.5)
        assert motor.target == pytest.approx(30.0 / TWO_PI)


def test_jog_is_stopped_by_the_watchdog(rig):
    ctl = rig.controller
    start = rig.motor_position('tilt')
    ctl.command(['tilt'], [], [5.0])       # +5 rad/s: the motor turns toward negative
    wait_for(lambda: rig.motor_moving('tilt'), TIMEOUT, 'tilt jogging')
    assert ctl.watchdog.jogging == ['tilt']
    # nothing feeds the jog: the watchdog stops it after command_timeout
    wait_for(lambda: not ctl.watchdog.jogging, TIMEOUT, 'the jog watchdog to expire')
    wait_for(lambda: not rig.motor_moving('tilt'), TIMEOUT, 'tilt stopped')
    stopped_at = rig.motor_position('tilt')
    assert -40.0 < stopped_at < start       # moved the SI-positive way, short of the end
    assert ctl.positions()['tilt'] > 0.0


def test_stop_halts_a_move(rig):
    ctl = rig.controller
    rig.motion.start_move(['slider'], [900.0], [30.0])
    wait_for(lambda: rig.motor_moving('slider'), TIMEOUT, 'slider moving')
    assert 'stopped' in ctl.stop()
    wait_for(lambda: not rig.motor_moving('slider'), TIMEOUT, 'slider stopped')
    assert rig.motor_position('slider') < 900.0 / TWO_PI - 1.0


def test_refusal_reasons_and_nothing_sent(rig):
    ctl = rig.controller
    before = rig.motor_commands()
    # outside the calibrated tilt range (0..+251 rad here): the device limit, before sending
    with pytest.raises(InvalidRequest, match=r"joint 'tilt'.*calibrated range"):
        rig.motion.start_move(['tilt'], [-1.0])
    with pytest.raises(InvalidRequest, match=r"joint 'pan'.*MaxMaxSetupSpeed"):
        rig.device.move({'pan': (10.0, 170.0 * TWO_PI)})
    with pytest.raises(InvalidRequest, match=r"joint 'pan'.*exceeds the motor maximum"):
        rig.device.jog({'pan': 170.0 * TWO_PI})
    assert rig.motor_commands() == before     # no motion command reached the device
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


def test_playback_owns_the_motors(rig):
    ctl = rig.controller
    frames = [Keyframe(0.0, {'pan': 10.0, 'tilt': 10.0}),
              Keyframe(4.0, {'pan': 100.0, 'tilt': 100.0})]
    rig.device.load_keyframes(frames, PlaybackSettings(loop_count=255, rapid_reverse=True))
    rig.device.start_playback()
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
    outcome = rig.motion.wait_move(rig.motion.start_move(['pan', 'tilt'], [15.0, 15.0]))
    assert outcome.success, outcome.message
    message = rig.motion.home(['pan', 'tilt'], lambda state: None)
    assert message == "at the begin mark: ['pan', 'tilt']"
    assert rig.motor_position('pan') == pytest.approx(0.0, abs=1e-3)
    assert rig.motor_position('tilt') == pytest.approx(0.0, abs=1e-3)


@pytest.mark.parametrize('end', ['cancel', 'stop'])
def test_a_homing_on_its_way_ends_at_a_cancel_request_or_a_stop(rig, end):
    """kOS homing reports once and then waits for the begin marks: a cancel request or a
    ~/stop must end that wait at once (it used to run on until move_timeout)."""
    outcome = rig.motion.wait_move(rig.motion.start_move(['pan'], [15.0]))
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
    wait_for(lambda: rig.controller.positions()['pan'] < 14.0, TIMEOUT,
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
    assert rig.controller.positions()['pan'] > 1.0  # stopped short of the begin mark


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
