"""The motion watch under a controller: an accepted command that shows no motion is
reported (diagnostics, one log line, a running goal ends at once), and nothing else is."""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Sequence

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.device import Device, DeviceInfo, JointSample, Moves
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.policies import Motion
from gimbal_driver_common.sim_control import SimControl
from gimbal_driver_common.sim_motion import AxisMotion
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.controller_rig import running_controller

JOINTS = ['pan', 'tilt']
#: the watch's timeout in these tests (s)
TIMEOUT = 0.2


class AxisDevice(Device):
    """Two shared-model axes stepped at each read: the simulators' motion model in-process,
    so ``ignore_commands`` is the simulators' ``ignore_motion`` fault."""

    def __init__(self, speed: float = 2.0, acceleration: float = 20.0) -> None:
        super().__init__()
        self.axes = {j: AxisMotion(max_speed=speed, acceleration=acceleration,
                                   min_position=-1.0, max_position=1.0) for j in JOINTS}
        self.lock = threading.Lock()
        self.last = time.monotonic()

    def open(self) -> DeviceInfo:
        return DeviceInfo('axes', 'SN2', '1.0')

    def read(self) -> JointSample:
        with self.lock:
            now = time.monotonic()
            for axis in self.axes.values():
                axis.step(now - self.last)
            self.last = now
            return JointSample({j: a.position for j, a in self.axes.items()},
                               {j: a.velocity for j, a in self.axes.items()})

    def move(self, moves: Moves) -> None:
        with self.lock:
            for joint, (target, speed) in moves.items():
                self.axes[joint].move_to(target, speed)

    def jog(self, velocities: dict[str, float]) -> None:
        with self.lock:
            for joint, velocity in velocities.items():
                self.axes[joint].jog(velocity)

    def stop(self, joints: Sequence[str] | None = None) -> None:
        with self.lock:
            for joint in joints or JOINTS:
                self.axes[joint].stop()

    def ignore(self, ignored: bool) -> None:
        for axis in self.axes.values():
            axis.ignore_commands = ignored


class Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())

    def stalls(self) -> list[str]:
        return [line for line in self.lines if 'commanded but not moving' in line]


def running(device: AxisDevice, log: logging.Logger,
            **overrides) -> contextlib.AbstractContextManager[GimbalController]:
    values = dict(joint_names=list(JOINTS),
                  limits={j: JointLimits(-1.0, 1.0, 2.0) for j in JOINTS},
                  publish_rate=200.0, command_timeout=0.0, reconnect_period=0.01,
                  goal_tolerance=0.01, move_timeout=20.0, motion_start_timeout=TIMEOUT)
    values.update(overrides)
    return running_controller(device, ControllerConfig(**values), log)


@pytest.fixture
def lines():
    handler = Lines()
    log = logging.getLogger(f'motion-watch-{id(handler)}')
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    log.propagate = False
    return log, handler


@pytest.fixture
def rig(lines):
    log, handler = lines
    device = AxisDevice()
    with running(device, log) as ctl:
        yield ctl, device, handler


def test_an_ignored_move_ends_the_goal_at_once_with_the_reason(rig) -> None:
    ctl, device, lines = rig
    device.ignore(True)
    motion = Motion(ctl)
    targets = motion.start_move(['pan'], [0.5])
    started = time.monotonic()
    outcome = motion.wait_move(targets)
    assert outcome.state == 'failed', outcome
    assert 'pan: commanded but not moving (target 0.5000, position 0.0000' in outcome.message
    # ends at the watch's timeout, long before move_timeout (20 s)
    assert time.monotonic() - started < ctl.config.move_timeout / 2
    assert len(lines.stalls()) == 1, lines.lines
    # the goal stopped the axis it could not move; the WARN stays for diagnostics to show
    # (the stop would otherwise clear it before the next publish), but nothing waits on it
    stalled = ctl.motion_watch.stalled()
    assert list(stalled) == ['pan'] and stalled['pan'].withdrawn, stalled
    assert ctl.motion_watch.reason(['pan']) is None
    time.sleep(3 * TIMEOUT)   # several samples of the stopped axis: still shown
    assert list(ctl.motion_watch.stalled()) == ['pan']
    # the next motion command for that axis clears it (and it moves this time)
    device.ignore(False)
    targets = motion.start_move(['pan'], [0.5])
    assert ctl.motion_watch.stalled() == {}
    assert motion.wait_move(targets).state == 'reached'
    assert ctl.motion_watch.stalled() == {} and len(lines.stalls()) == 1, lines.lines


def test_the_warn_of_one_axis_stays_through_commands_to_another(rig) -> None:
    """Per axis: a move_to of tilt (which preempts everything) leaves pan's WARN shown; the
    axis moving clears it (here the device moves it by itself)."""
    ctl, device, lines = rig
    device.ignore(True)
    motion = Motion(ctl)
    assert motion.wait_move(motion.start_move(['pan'], [0.5])).state == 'failed'
    device.ignore(False)
    assert motion.wait_move(motion.start_move(['tilt'], [0.3])).state == 'reached'
    assert list(ctl.motion_watch.stalled()) == ['pan']
    with device.lock:
        device.axes['pan'].move_to(-0.5)   # motion the driver did not command
    wait_for(lambda: not ctl.motion_watch.stalled(), 5.0, 'pan moving to clear its WARN')
    assert len(lines.stalls()) == 1, lines.lines


def test_a_command_stopped_before_it_stalls_is_never_reported(rig) -> None:
    ctl, device, lines = rig
    device.ignore(True)
    ctl.command(['pan'], [0.5], [])
    ctl.stop()
    time.sleep(4 * TIMEOUT)
    assert ctl.motion_watch.stalled() == {}
    assert lines.stalls() == []


def test_a_command_stream_to_an_axis_that_ignores_it_is_reported_once(rig) -> None:
    ctl, device, lines = rig
    device.ignore(True)
    deadline = time.monotonic() + 6 * TIMEOUT
    target = 0.3
    while time.monotonic() < deadline:  # a new target every 10 ms never resets the clock
        target += 0.001
        ctl.command(['tilt'], [target], [])
        time.sleep(0.01)
    wait_for(lambda: ctl.motion_watch.stalled().get('tilt') and
             ctl.motion_watch.stalled()['tilt'].target == pytest.approx(target), 5.0,
             'the newest target in the report')
    stalled = ctl.motion_watch.stalled()
    assert list(stalled) == ['tilt'], stalled
    assert stalled['tilt'].position == 0.0
    assert len(lines.stalls()) == 1, lines.lines
    ctl.stop()  # withdrawn, still shown until the next command for tilt
    assert ctl.motion_watch.stalled()['tilt'].withdrawn
    device.ignore(False)
    ctl.command(['tilt'], [target], [])  # sent by the command thread unless it can post
    wait_for(lambda: ctl.motion_watch.stalled() == {}, 5.0, 'the report ended by the command')


def test_an_ignored_jog_is_reported_until_the_next_jog(rig) -> None:
    ctl, device, lines = rig
    device.ignore(True)
    ctl.command(['pan'], [], [0.4])
    wait_for(lambda: 'pan' in ctl.motion_watch.stalled(), 5.0, 'the jog to be reported')
    assert ctl.motion_watch.stalled()['pan'].target is None
    assert 'jog +0.4000/s' in ctl.motion_watch.reason(['pan'])
    assert len(lines.stalls()) == 1, lines.lines
    ctl.command(['pan'], [], [0.0])  # a zero jog is a stop: the WARN stays shown
    wait_for(lambda: ctl.motion_watch.stalled()['pan'].withdrawn, 5.0, 'the stop sent')
    time.sleep(3 * TIMEOUT)  # and stays shown while nothing moves
    assert ctl.motion_watch.stalled()['pan'].withdrawn
    assert ctl.motion_watch.reason(['pan']) is None
    device.ignore(False)
    ctl.command(['pan'], [], [0.4])  # the next jog clears it, and moves
    wait_for(lambda: device.axes['pan'].position > 0.01, 5.0, 'pan to jog')
    assert ctl.motion_watch.stalled() == {}
    ctl.command(['pan'], [], [0.0])
    assert len(lines.stalls()) == 1, lines.lines


def test_a_jog_streamed_into_its_limit_is_not_reported(rig) -> None:
    """A controller feeds the dead-man watchdog with the same jog; the axis runs into its
    limit and rests there: that is the jog carried out, not a stall."""
    ctl, device, lines = rig
    device.axes['pan'].max_position = 0.05   # the device's own end stop, near by
    deadline = time.monotonic() + 0.2
    while time.monotonic() < deadline:  # until it has moved
        ctl.command(['pan'], [], [0.5])
        time.sleep(0.01)
    wait_for(lambda: device.axes['pan'].position >= 0.05, 5.0, 'pan at its end stop')
    end = time.monotonic() + 6 * TIMEOUT
    while time.monotonic() < end:   # the jog goes on at the limit for several timeouts
        ctl.command(['pan'], [], [0.5])
        time.sleep(0.01)
    assert ctl.motion_watch.stalled() == {}
    assert lines.stalls() == []
    ctl.command(['pan'], [], [-0.5])   # the other way is a new jog, watched again
    wait_for(lambda: device.axes['pan'].position < 0.04, 5.0, 'pan back off the stop')
    assert ctl.motion_watch.stalled() == {}


def test_moves_and_jogs_that_move_are_never_reported(lines) -> None:
    log, handler = lines
    # slow: 0.05 rad/s at 0.1 rad/s^2 moves far less than the goal tolerance per timeout
    device = AxisDevice(speed=0.05, acceleration=0.1)
    with running(device, log) as ctl:
        ctl.command(['pan'], [0.05], [])
        ctl.command(['tilt'], [], [0.03])
        time.sleep(6 * TIMEOUT)   # several timeouts while both axes creep
        assert ctl.motion_watch.stalled() == {}
        assert handler.stalls() == []
        assert device.axes['pan'].position > 0.0 and device.axes['tilt'].position > 0.0


def test_an_axis_at_its_target_or_a_disabled_watch_is_never_reported(lines) -> None:
    log, handler = lines
    device = AxisDevice()
    with running(device, log) as ctl:
        device.ignore(True)
        ctl.command(['pan'], [0.005], [])   # within goal_tolerance of 0.0
        time.sleep(4 * TIMEOUT)
        assert ctl.motion_watch.stalled() == {}
        ctl.config.motion_start_timeout = 0.0   # disabled
        ctl.command(['pan'], [0.5], [])
        time.sleep(4 * TIMEOUT)
        assert ctl.motion_watch.stalled() == {}
        assert handler.stalls() == []


def test_the_simulators_ignore_motion_verb_drops_commands_of_axes_at_rest() -> None:
    axes = [AxisMotion(max_speed=1.0, acceleration=10.0) for _ in range(2)]
    control = SimControl('sim', lambda: {}, axes=lambda: axes)
    assert control.execute('ignore_motion on').startswith('ok 2 axes ignore')
    axes[0].move_to(0.5)
    axes[1].jog(0.5)
    for axis in axes:
        axis.step(0.1)
    assert [a.position for a in axes] == [0.0, 0.0]
    assert control.execute('clear') == 'ok'
    axes[0].move_to(0.5)
    axes[0].step(0.1)
    assert axes[0].position > 0.0
    no_axes = SimControl('other', lambda: {})
    assert no_axes.execute('ignore_motion on').startswith('error ignore_motion: not applicable')

