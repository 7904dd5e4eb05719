"""Every stop reaches rest: all steps go out whatever one of them does, and the axis
confirms the stop (resent at a bounded rate until at rest, ERROR while it does not, logged
once, the dead-man stop keeps the joint). On an injected clock, a controller that is not
opened (no threads): the test is the device thread and the housekeeping thread."""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Sequence
from typing import NamedTuple

import pytest

from gimbal_driver_common.controller import (
    STOP_CHECK_IDLE_S,
    STOP_CHECK_S,
    ControllerConfig,
    GimbalController,
    LinkState,
    is_moving,
)
from gimbal_driver_common.device import Device, DeviceInfo, DeviceScans, JointSample, Moves
from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout, GimbalError
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.policies import Motion
from gimbal_driver_common.ros.messages import with_axis_parts
from gimbal_driver_common.scan import ScanRequest
from gimbal_driver_common.stop_watch import RESEND_PERIOD_S, StopWatch
from gimbal_driver_testing import ManualClock, wait_for
from gimbal_driver_testing.controller_rig import running_controller

JOINTS = ['pan', 'tilt']
DECELERATION = 1.0   # rad/s^2 the controller is configured with
MARGIN = 0.5         # s


class JogAxes(Device):
    """Axes that jog at the velocity sent and stop at once; ``drop_stops`` stops are
    taken as the device would and not acted on; ``fail`` names steps that raise."""

    def __init__(self) -> None:
        super().__init__()
        self.velocities = dict.fromkeys(JOINTS, 0.0)
        self.positions = dict.fromkeys(JOINTS, 0.0)
        self.drop_stops = 0
        self.fail: dict[str, GimbalError] = {}
        self.sent: list[tuple[str, object]] = []
        self.lock = threading.Lock()

    def open(self) -> DeviceInfo:
        return DeviceInfo('jog axes', 'SN3', '1.0')

    def read(self) -> JointSample:
        with self.lock:
            for joint, velocity in self.velocities.items():
                self.positions[joint] += velocity * 0.02
            return JointSample(dict(self.positions), dict(self.velocities))

    def move(self, moves: Moves) -> None:
        raise AssertionError('no moves here')

    def jog(self, velocities: dict[str, float]) -> None:
        with self.lock:
            self.sent.append(('jog', dict(velocities)))
            self.velocities.update(velocities)

    def stop(self, joints: Sequence[str] | None = None) -> None:
        with self.lock:
            self.sent.append(('stop', None if joints is None else list(joints)))
            if 'stop' in self.fail:
                raise self.fail['stop']
            if self.drop_stops:
                self.drop_stops -= 1
                return
            for joint in joints or JOINTS:
                self.velocities[joint] = 0.0

    def stops(self) -> int:
        with self.lock:
            return sum(1 for kind, _ in self.sent if kind == 'stop')


class Scans(DeviceScans):
    patterns = ('sector',)

    def __init__(self, device: JogAxes) -> None:
        self.device = device

    def start(self, request: ScanRequest) -> str:
        return 'scanning'

    def stop(self) -> None:
        with self.device.lock:
            self.device.sent.append(('scan_stop', None))
        if 'scan_stop' in self.device.fail:
            raise self.device.fail['scan_stop']


class Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.lines: list[tuple[int, str]] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append((record.levelno, record.getMessage()))

    def errors(self, text: str) -> list[str]:
        return [m for level, m in self.lines if level >= logging.ERROR and text in m]


def config(**overrides: object) -> ControllerConfig:
    values: dict = dict(joint_names=list(JOINTS),
                        limits={j: JointLimits(-3.0, 3.0, 2.0) for j in JOINTS},
                        command_timeout=0.5, stop_deceleration=DECELERATION,
                        stop_margin=MARGIN)
    values.update(overrides)
    return ControllerConfig(**values)


@pytest.fixture
def rig():
    clock, device, lines = ManualClock(), JogAxes(), Lines()
    log = logging.getLogger(f'test_stop_watch.{id(clock)}')
    log.addHandler(lines)
    log.propagate = False
    ctl = GimbalController(device, config(), log, clock=clock)
    ctl.link_state, ctl.active = LinkState.CONNECTED, True  # opened by hand: no threads
    ctl.stop_watch.observe(device.read(), clock())
    yield Rig(ctl, device, clock, lines)
    ctl.periodic.stop()
    ctl.sensors.stop()


class Rig:
    """Plays the device thread (a sample per tick) and the housekeeping thread."""

    def __init__(self, ctl: GimbalController, device: JogAxes, clock: ManualClock,
                 lines: Lines) -> None:
        self.ctl, self.device, self.clock, self.lines = ctl, device, clock, lines

    def tick(self, seconds: float = 0.02) -> None:
        self.clock.now += seconds
        sample = self.device.read()
        self.ctl.latest = sample
        self.ctl.stop_watch.observe(sample, self.clock())
        self.ctl.watchdog_job.run()  # as the housekeeping thread runs them: paced
        self.ctl.stop_job.run()

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / 0.02)):
            self.tick()

    def jog(self, joint: str, velocity: float, dead_man: bool = False) -> None:
        """A jog sent as the command path sends it (fed to the watchdog if ``dead_man``)."""
        if dead_man:
            self.ctl.watchdog.feed([joint])
        self.device.jog({joint: velocity})
        self.tick()

    def diagnostics(self) -> dict[str, tuple[int, str]]:
        parts = with_axis_parts([], self.ctl, list(JOINTS))
        return {p.part: (int(p.level), p.message) for p in parts}


# --------------------------------------------------------------- every step goes out
def test_a_failing_step_skips_no_other_and_every_failure_is_reported(rig) -> None:
    rig.device.capabilities.scans = Scans(rig.device)
    rig.device.fail = {'stop': DeviceTimeout('MOT_SetSpeedMode: no reply'),
                       'scan_stop': DeviceRefused('scan stop NACK')}
    with pytest.raises(GimbalError) as raised:
        rig.ctl.stops.send(None)
    assert [kind for kind, _ in rig.device.sent] == ['stop', 'scan_stop']  # motion first
    assert 'MOT_SetSpeedMode: no reply' in str(raised.value)
    assert 'scan stop NACK' in str(raised.value)


def test_a_device_whose_stop_ends_its_scans_is_sent_its_stop_once(rig) -> None:
    """Capture's whole stop ends with SCN_StopScan: a scans object that says so
    (``stopped_by_device_stop``) is not stopped again after it; a partial stop and a
    device that does not say so are as before."""
    scans = rig.device.capabilities.scans = Scans(rig.device)
    scans.stopped_by_device_stop = True
    rig.ctl.stops.send(None)
    assert [kind for kind, _ in rig.device.sent] == ['stop']  # once: not again as scans
    scans.stopped_by_device_stop = False
    rig.ctl.stops.send(None)
    rig.ctl.stops.send(['pan'])  # a partial stop never stops scans
    assert [kind for kind, _ in rig.device.sent] == ['stop', 'stop', 'scan_stop', 'stop']


def test_the_device_is_stopped_even_when_the_scan_stop_fails(rig) -> None:
    rig.device.capabilities.scans = Scans(rig.device)
    rig.device.fail = {'scan_stop': DeviceTimeout('SCN_StopScan: no reply')}
    rig.jog('pan', 0.3)
    rig.ctl.halt('test')
    assert ('stop', None) in rig.device.sent
    rig.tick()
    assert rig.ctl.stop_watch.at_rest('pan')


# --------------------------------------------------------------- confirmation
def test_a_dropped_stop_is_sent_again_at_a_bounded_rate_until_the_axis_rests(rig) -> None:
    rig.jog('pan', 0.3)
    rig.device.drop_stops = 1_000_000  # never takes it: the watch must never give up
    rig.ctl.stop_joints(['pan'])
    settle = 0.3 / DECELERATION + MARGIN
    rig.run(settle - 0.1)
    assert rig.device.stops() == 1  # within its deceleration time: not yet
    observed = 20.0
    rig.run(observed)
    resends = rig.device.stops() - 1
    assert resends >= 1
    assert resends <= observed / RESEND_PERIOD_S + 1  # bounded rate, never a burst
    assert not rig.ctl.stop_watch.at_rest('pan')  # never gives up
    rig.device.drop_stops = 0
    rig.run(2 * RESEND_PERIOD_S)
    assert rig.ctl.stop_watch.at_rest('pan') and rig.device.velocities['pan'] == 0.0
    sent = rig.device.stops()
    rig.run(2.0)
    assert rig.device.stops() == sent  # at rest: nothing more


def test_the_confirmation_looks_often_from_the_stop_until_the_axis_rests(rig) -> None:
    """Idle: the slow period; the stop switches to STOP_CHECK_S at once (before the
    housekeeping thread's next look), and it stays fast through every resend until rest."""
    assert rig.ctl.stop_job.period() == STOP_CHECK_IDLE_S
    rig.jog('pan', 0.3)
    assert rig.ctl.stop_job.period() == STOP_CHECK_IDLE_S  # a jog is no stop
    rig.device.drop_stops = 3
    rig.ctl.stop_joints(['pan'])
    assert rig.ctl.stop_job.period() == STOP_CHECK_S
    start = rig.clock()
    while not rig.ctl.stop_watch.at_rest('pan'):
        assert rig.clock() - start < 60.0, 'the axis never came to rest'
        assert rig.ctl.stop_job.period() == STOP_CHECK_S
        rig.tick()
    assert rig.device.stops() == 4  # three dropped, sent again until one was taken
    assert rig.ctl.stop_job.period() == STOP_CHECK_IDLE_S


def test_an_unconfirmed_stop_reads_error_and_is_logged_once_per_episode(rig) -> None:
    rig.jog('pan', 0.3)
    rig.device.drop_stops = 3
    rig.ctl.stop_joints(['pan'])
    assert rig.diagnostics()['pan'][0] == 0  # still braking: OK
    rig.run(0.3 / DECELERATION + MARGIN + 2 * RESEND_PERIOD_S)
    level, message = rig.diagnostics()['pan']
    assert level == 2, message
    assert 'stop not confirmed: still moving at 0.300 rad/s, stop sent' in message
    assert rig.diagnostics()['tilt'][0] == 0
    rig.run(5.0)
    assert rig.ctl.stop_watch.at_rest('pan')
    assert rig.diagnostics()['pan'][0] == 0
    assert len(rig.lines.errors('stop not confirmed')) == 1, rig.lines.lines
    # a new episode is logged again
    rig.jog('pan', 0.3)
    rig.device.drop_stops = 2
    rig.ctl.stop_joints(['pan'])
    rig.run(5.0)
    assert len(rig.lines.errors('stop not confirmed')) == 2, rig.lines.lines


def test_the_dead_man_keeps_the_joint_until_its_axis_rests(rig) -> None:
    rig.jog('pan', 0.3, dead_man=True)
    rig.device.drop_stops = 4
    rig.run(rig.ctl.config.command_timeout + 0.1)  # the jog expires: the dead-man stop
    assert rig.ctl.watchdog.stopping == ['pan'] and rig.device.stops() == 1
    rig.run(0.3 / DECELERATION + MARGIN + 0.1)
    assert rig.ctl.watchdog.stopping == ['pan']  # still moving: kept
    rig.run(10.0)
    assert rig.device.stops() == 5 and rig.device.velocities['pan'] == 0.0
    assert rig.ctl.watchdog.stopping == []


def test_a_new_command_ends_the_confirmation(rig) -> None:
    rig.jog('pan', 0.3)
    rig.device.drop_stops = 1_000_000
    rig.ctl.stop_joints(['pan'])
    rig.run(2.0)
    sent = rig.device.stops()
    rig.ctl.command(['pan'], [math.nan], [-0.2])  # the operator jogs it again
    assert rig.ctl.stop_watch.at_rest('pan')
    rig.run(rig.ctl.config.command_timeout - 0.1)  # more than a resend period; no dead-man
    assert rig.device.stops() == sent


def test_a_motion_policy_ends_the_confirmation(rig) -> None:
    motion = Motion(rig.ctl)
    rig.jog('pan', 0.3)
    rig.device.drop_stops = 1_000_000
    rig.ctl.stop_joints(['pan'])
    motion.preempt()  # what a move, preset, scan or homing does first
    assert rig.ctl.stop_watch.at_rest('pan')


def velocity_watch(clock: ManualClock) -> StopWatch:
    """A watch on ``clock`` whose moving rule is a non-zero velocity."""
    return StopWatch(lambda: DECELERATION, lambda: MARGIN,
                     lambda sample, joint: bool(sample and sample.velocities.get(joint)),
                     logging.getLogger('test'), clock=clock)


def test_a_sample_read_before_the_stop_confirms_nothing() -> None:
    clock = ManualClock()
    watch = velocity_watch(clock)
    watch.observe(JointSample({'pan': 0.0}, {'pan': 0.3}), clock())
    read_at = clock()
    clock.now += 0.01
    watch.stopped(['pan'])
    watch.observe(JointSample({'pan': 0.0}, {'pan': 0.0}), read_at)  # began before the stop
    assert not watch.at_rest('pan')
    watch.observe(JointSample({'pan': 0.0}, {'pan': 0.0}), clock())
    assert watch.at_rest('pan')


def test_an_unknown_speed_confirms_nothing() -> None:
    """A sample whose speed is NaN (its report stale or missing) and that has no moving
    bit says nothing of rest: the moving rule alone reads NaN as slow."""
    clock = ManualClock()
    watch = StopWatch(lambda: DECELERATION, lambda: MARGIN, is_moving,
                      logging.getLogger('test'), clock=clock)
    watch.observe(JointSample({'pan': 0.0}, {'pan': 0.3}), clock())
    watch.stopped(['pan'])
    watch.observe(JointSample({'pan': 0.1}, {'pan': math.nan}), clock())
    assert not watch.at_rest('pan')
    watch.observe(JointSample({'pan': 0.1}, {'pan': math.nan}, moving={'pan': False}),
                  clock())  # the device's own bit
    assert watch.at_rest('pan')


def test_wait_returns_the_axes_still_moving_after_their_time() -> None:
    clock = ManualClock()
    watch = velocity_watch(clock)
    watch.observe(JointSample({'pan': 0.0, 'tilt': 0.0}, {'pan': 0.3, 'tilt': 0.0}), clock())
    watch.stopped(['pan', 'tilt'])
    assert watch.settle_time('pan') == pytest.approx(0.3 / DECELERATION + MARGIN)

    def samples(condition: threading.Condition, left: float) -> None:
        clock.now += 0.1  # each wake-up is one sample: tilt at rest, pan moving
        watch._changed.release()
        try:
            watch.observe(JointSample({'pan': 0.0, 'tilt': 0.0}, {'pan': 0.3, 'tilt': 0.0}),
                          clock())
        finally:
            watch._changed.acquire()

    assert watch.wait(['pan', 'tilt'], watch.settle_time('pan'), samples) == ['pan']


def test_an_axis_a_newer_command_moves_during_the_wait_is_not_at_rest() -> None:
    """A jog published just before ``~/stop`` can reach the node just after it (two
    topics, no order between them): the jog ends the stop's episode, and the wait must not
    read that as rest (a loaded run answered ``~/stop`` success while the jog ran)."""
    clock = ManualClock()
    watch = velocity_watch(clock)
    watch.observe(JointSample({'pan': 0.0, 'tilt': 0.0}, {'pan': 0.3, 'tilt': 0.3}), clock())
    watch.stopped(['pan', 'tilt'])
    woken: list[float] = []

    def newer_jog_then_rest(condition: threading.Condition, left: float) -> None:
        woken.append(left)
        clock.now += 0.05
        condition.release()
        try:
            if len(woken) == 1:
                watch.superseded(['pan'])  # the late jog: pan moves by it
            watch.observe(JointSample({'pan': 0.0, 'tilt': 0.0}, {'pan': 0.3, 'tilt': 0.0}),
                          clock())
        finally:
            condition.acquire()

    moving = watch.wait(['pan', 'tilt'], watch.settle_time('pan'), newer_jog_then_rest)
    assert moving == ['pan']
    assert len(woken) == 1  # returned once tilt rested: pan waits for no stop of its own
    assert watch.still_moving(moving) == 'stop not confirmed: pan moved by a newer motion command'
    # a wait that begins after the newer command reads only its own stops
    assert watch.wait(['pan', 'tilt'], 1.0, newer_jog_then_rest) == []


# --------------------------------------------------------------- ~/stop tells the truth
class ThreadedRig(NamedTuple):
    """The controller with its threads, on the real clock (the service's wait)."""

    ctl: GimbalController
    device: JogAxes


@pytest.fixture
def threaded():
    device = JogAxes()
    with running_controller(device, config(stop_margin=0.2),
                            logging.getLogger('test_stop_truth')) as ctl:
        try:
            yield ThreadedRig(ctl, device)
        finally:
            device.drop_stops = 0   # the shutdown's stop is taken


def test_stop_answers_success_only_at_rest(threaded) -> None:
    threaded.ctl.command(['pan'], [math.nan], [0.3])
    wait_for(lambda: threaded.ctl.moving('pan'), 5.0, 'pan jogging')
    assert threaded.ctl.stop().startswith('all axes stopped and at rest')
    assert not threaded.ctl.moving('pan')


def test_stop_answers_failure_naming_the_axis_that_still_moves(threaded) -> None:
    threaded.ctl.command(['pan'], [math.nan], [0.3])
    wait_for(lambda: threaded.ctl.moving('pan'), 5.0, 'pan jogging')
    threaded.device.drop_stops = 1_000_000
    with pytest.raises(DeviceRefused) as refused:
        threaded.ctl.stop()
    assert 'stop not confirmed: pan still moving at 0.300 rad/s, stop sent' in \
        str(refused.value)
    assert 'tilt' not in str(refused.value)
    threaded.device.drop_stops = 0
    wait_for(lambda: threaded.ctl.stop_watch.at_rest('pan'), 10.0, 'the resent stop')
    assert threaded.device.velocities['pan'] == 0.0
