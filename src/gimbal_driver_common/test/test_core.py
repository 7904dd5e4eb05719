"""Watchdog, presets, joint-command validation, register decoding, scans."""

from __future__ import annotations

import math

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from gimbal_driver_common.diagnostics import (
    FrequencyMonitor,
    Level,
    RegisterFlag,
    decode_register,
    flags_to_key_values,
    summarize,
    worst_level,
)
from gimbal_driver_common.joint_command import (
    CommandError,
    JointLimits,
    limits_from_parameters,
    resolve_targets,
    validate_joint_command,
    validate_targets,
)
from gimbal_driver_common.presets import PresetError, PresetStore
from gimbal_driver_common.scan import ScanError, ScanRequest, plan_scan
from gimbal_driver_common.watchdog import JogWatchdog
from gimbal_driver_testing import ManualClock

LIMITS = {
    'pan': JointLimits(-3.0, 3.0, 1.0),
    'tilt': JointLimits(-1.0, 1.0, 0.5),
}


# ------------------------------------------------------------------ watchdog
def test_watchdog_expires_only_unfed_joints() -> None:
    clock = ManualClock()
    expired: list[list[str]] = []
    dog = JogWatchdog(0.5, expired.append, clock)
    dog.feed(['pan', 'tilt'])
    clock.now += 0.3
    dog.feed(['tilt'])
    assert dog.check() == []
    clock.now += 0.25
    assert dog.check() == ['pan']
    assert expired == [['pan']]
    assert dog.jogging == ['tilt']
    clock.now += 0.5
    assert dog.check() == ['tilt']
    assert dog.check() == []  # reported once


def test_watchdog_cancel_and_disable() -> None:
    clock = ManualClock()
    dog = JogWatchdog(0.5, None, clock)
    dog.feed(['pan'])
    dog.cancel(['pan'])
    clock.now += 1
    assert dog.check() == []
    off = JogWatchdog(0.0, None, clock)
    off.feed(['pan'])
    clock.now += 100
    assert not off.enabled and off.check() == []


# ------------------------------------------------------------------- presets
def test_presets_persist_across_instances(tmp_path) -> None:
    path = tmp_path / 'sub' / 'presets.yaml'
    store = PresetStore(str(path))
    store.set(3, 'door', {'pan': 1.0, 'tilt': -0.5})
    store.set(1, 'home', {'pan': 0.0, 'tilt': 0.0})
    again = PresetStore(str(path))
    assert [p.index for p in again.list()] == [1, 3]
    assert again.get(3).positions == {'pan': 1.0, 'tilt': -0.5}
    again.clear(3)
    assert [p.index for p in PresetStore(str(path)).list()] == [1]
    again.clear()
    assert PresetStore(str(path)).list() == []


def test_presets_errors(tmp_path) -> None:
    store = PresetStore('')
    with pytest.raises(PresetError, match='no preset 7'):
        store.get(7)
    with pytest.raises(PresetError, match='no preset 7'):
        store.clear(7)
    with pytest.raises(PresetError, match='not finite'):
        store.set(1, 'x', {'pan': math.nan})
    with pytest.raises(PresetError, match='out of range'):
        store.set(70000, 'x', {'pan': 0.0})
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump({'presets': [{'index': 'x'}]}))
    with pytest.raises(PresetError, match='malformed'):
        PresetStore(str(bad))


# ------------------------------------------------------------- joint command
def test_joint_command_moves_and_jogs() -> None:
    plan = validate_joint_command(['pan', 'tilt'], [1.0, math.nan], [0.5, -0.2], LIMITS)
    assert plan.moves == {'pan': (1.0, 0.5)}
    assert plan.jogs == {'tilt': -0.2}
    plan = validate_joint_command(['tilt'], [0.5], [], LIMITS)
    assert plan.moves == {'tilt': (0.5, None)}


@pytest.mark.parametrize(
    ('names', 'positions', 'velocities', 'message'),
    [
        (['roll'], [0.0], [], 'unknown joint'),
        (['pan'], [math.inf], [], 'not a finite number'),
        (['pan', 'tilt'], [math.nan, -math.inf], [], 'not a finite number'),
        (['pan'], [math.nan], [math.inf], 'not a finite number'),
        (['pan'], [3.5], [], r'outside \[-3.0000, 3.0000\]'),
        (['tilt'], [], [0.6], 'exceeds velocity_max'),
        (['pan', 'pan'], [0.0, 0.0], [], 'twice'),
        (['pan', 'tilt'], [0.0], [], '2 joint names but 1 position'),
        ([], [], [], 'no joints'),
    ],
)
def test_joint_command_rejections(names, positions, velocities, message) -> None:
    with pytest.raises(CommandError, match=message):
        validate_joint_command(names, positions, velocities, LIMITS)


def test_nan_means_no_command_for_that_joint() -> None:
    """ros2_control's topic interface sends NaN for joints whose controller has not
    written a command: those joints are left out, the others carried out."""
    plan = validate_joint_command(['pan', 'tilt'], [0.5, math.nan], [], LIMITS)
    assert plan.moves == {'pan': (0.5, None)} and plan.jogs == {}
    plan = validate_joint_command(['pan', 'tilt'], [math.nan, math.nan], [math.nan, 0.2],
                                  LIMITS)
    assert plan.moves == {} and plan.jogs == {'tilt': 0.2}
    for positions, velocities in (([math.nan] * 2, []), ([math.nan] * 2, [math.nan] * 2),
                                  ([], [math.nan] * 2)):
        assert validate_joint_command(['pan', 'tilt'], positions, velocities, LIMITS).empty
    # a NaN speed beside a position: the default speed
    assert validate_joint_command(['pan'], [0.1], [math.nan], LIMITS).moves == {
        'pan': (0.1, None)}


def test_targets_that_must_be_reached_refuse_nan() -> None:
    """A MoveTo goal or a preset names every joint it wants: NaN is an error there."""
    with pytest.raises(CommandError, match="'tilt': position NaN is not a target"):
        validate_targets(['pan', 'tilt'], [0.1, math.nan], LIMITS)
    with pytest.raises(CommandError, match='NaN is not a target'):
        resolve_targets(['pan'], [math.nan], {'pan': 0.0}, LIMITS)
    with pytest.raises(CommandError, match='NaN is not a target'):
        resolve_targets(['pan'], [math.nan], {'pan': 0.0}, LIMITS, relative=True)
    with pytest.raises(CommandError, match='received yet'):
        resolve_targets(['pan'], [0.1], {}, LIMITS, relative=True)
    with pytest.raises(CommandError, match='exceeds velocity_max'):
        validate_targets(['pan'], [0.1], LIMITS, speeds=[5.0])
    assert validate_targets(['pan', 'tilt'], [0.1, 0.2], LIMITS, speeds=[0.5, 0.0]) == {
        'pan': (0.1, 0.5), 'tilt': (0.2, None)}


def test_rejection_reasons_leave_the_values_out() -> None:
    """Two rejections for the same cause share one reason (what is counted and throttled)."""
    reasons = set()
    for position in (3.5, 4.25, -7.0):
        with pytest.raises(CommandError) as caught:
            validate_joint_command(['pan'], [position], [], LIMITS)
        assert str(position) in str(caught.value) or f'{position:.4f}' in str(caught.value)
        reasons.add(caught.value.reason)
    assert reasons == {'pan: position outside the limits'}
    with pytest.raises(CommandError) as caught:
        validate_joint_command(['tilt'], [], [0.9], LIMITS)
    assert caught.value.reason == 'tilt: velocity above velocity_max'


@given(
    st.lists(st.sampled_from(['pan', 'tilt', 'x']), max_size=3),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=3),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=3),
)
def test_joint_command_never_raises_anything_else(names, positions, velocities) -> None:
    try:
        plan = validate_joint_command(names, positions, velocities, LIMITS)
    except CommandError:
        return
    for name, (position, speed) in plan.moves.items():
        assert LIMITS[name].position_min <= position <= LIMITS[name].position_max
        assert speed is None or speed <= LIMITS[name].velocity_max
    for name, velocity in plan.jogs.items():
        assert abs(velocity) <= LIMITS[name].velocity_max


def test_relative_targets_and_limits_from_parameters() -> None:
    targets = resolve_targets(['pan'], [0.5], {'pan': 2.0}, LIMITS, relative=True)
    assert targets == {'pan': 2.5}
    with pytest.raises(CommandError, match='outside'):
        resolve_targets(['pan'], [1.5], {'pan': 2.0}, LIMITS, relative=True)
    limits = limits_from_parameters(['a', 'b'], [-1, -2], [1, 2], [0.1, 0.2])
    assert limits['b'] == JointLimits(-2, 2, 0.2)
    with pytest.raises(ValueError, match='position_max has 1 values'):
        limits_from_parameters(['a', 'b'], [-1, -2], [1], [0.1, 0.2])
    with pytest.raises(ValueError, match="joint 'a'"):
        limits_from_parameters(['a'], [1], [-1], [0.1])


# --------------------------------------------------------------- diagnostics
FLAGS = [
    RegisterFlag(0, 'moving', Level.OK, 'axis moving'),
    RegisterFlag(1, 'overcurrent', Level.ERROR, 'motor overcurrent'),
    RegisterFlag(2, 'soft_limit', Level.WARN, 'software limit reached'),
    RegisterFlag(7, 'not_powered', Level.WARN, 'axis not powered', active_low=True),
]


def test_decode_register_and_summary() -> None:
    active = decode_register(0b1000_0011, FLAGS, 'MER')
    assert [a.key for a in active] == ['MER.moving', 'MER.overcurrent']
    level, message = summarize(active)
    assert level == Level.ERROR and message == 'motor overcurrent'
    assert ('MER.overcurrent', 'motor overcurrent') in flags_to_key_values(active)
    active = decode_register(0b0000_0100, FLAGS, 'MER')
    assert [a.flag.name for a in active] == ['soft_limit', 'not_powered']
    assert summarize(active)[0] == Level.WARN
    assert summarize(decode_register(0x81, FLAGS))[0] == Level.OK


def test_worst_level_and_frequency_monitor() -> None:
    assert worst_level([]) == Level.OK
    assert worst_level([Level.STALE]) == Level.STALE
    assert worst_level([Level.STALE, Level.WARN]) == Level.WARN
    assert worst_level([Level.ERROR, Level.WARN]) == Level.ERROR
    monitor = FrequencyMonitor(50.0)
    monitor.sample(0.0)
    for _ in range(50):
        monitor.tick()
    monitor.sample(1.0)
    assert monitor.status()[0] == Level.OK
    for _ in range(20):
        monitor.tick()
    monitor.sample(2.0)
    assert monitor.status()[0] == Level.WARN
    monitor.sample(3.0)
    monitor.sample(4.0)
    monitor.sample(5.0)
    monitor.sample(6.0)
    assert monitor.status() == (Level.ERROR, 'no events')



def test_a_pause_in_publishing_does_not_read_as_a_low_rate_afterwards() -> None:
    """Samples taken while the node was inactive (or the link down) would put a stretch
    without joint_states in the window: a healthy device read WARN after activation."""
    monitor = FrequencyMonitor(50.0)
    monitor.sample(0.0, live=False)  # inactive: no joint_states yet
    monitor.sample(1.0, live=False)
    for _ in range(25):  # activated at 1.5 s: 50 Hz from then on
        monitor.tick()
    monitor.sample(2.0)
    assert monitor.status() == (Level.OK, 'measuring')
    for _ in range(50):
        monitor.tick()
    monitor.sample(3.0)
    assert monitor.status() == (Level.OK, '50.0 Hz')

def test_a_new_publish_rate_restarts_the_window() -> None:
    """diagnostic_updater's FrequencyStatus.clear(): after publish_rate goes from 10 to 50
    Hz the window no longer mixes both rates (it read "too low" for a whole window)."""
    def run(monitor: FrequencyMonitor, start: float, rate: int, periods: int) -> float:
        for step in range(periods):
            for _ in range(rate):
                monitor.tick()
            monitor.sample(start + step + 1)
        return start + periods

    restarted, mixed = FrequencyMonitor(10.0), FrequencyMonitor(10.0)
    for monitor in (restarted, mixed):
        monitor.sample(0.0)
        monitor.follow_publish_rate(10.0)
        run(monitor, 0.0, 10, 5)
        assert monitor.status() == (Level.OK, '10.0 Hz')
    restarted.follow_publish_rate(10.0)   # unchanged: the window goes on
    assert restarted.status() == (Level.OK, '10.0 Hz')
    # the rate changes at 5 s; the first diagnostics period after it is at 6 s
    for monitor in (restarted, mixed):
        monitor.expected_hz = 50.0
        run(monitor, 5.0, 50, 1)
    restarted.follow_publish_rate(50.0)
    assert restarted.status() == (Level.OK, 'measuring')
    assert mixed.status()[0] == Level.WARN   # without the restart: 20 Hz, "too low"
    run(restarted, 6.0, 50, 1)
    run(mixed, 6.0, 50, 1)
    assert restarted.status() == (Level.OK, '50.0 Hz')
    assert restarted.rate_hz == 50.0
    assert 'too low' in mixed.status()[1]
    restarted.sample(8.0, live=False)   # a pause still empties it
    assert restarted.status() == (Level.OK, 'measuring')


# --------------------------------------------------------------------- scans
def scan(pattern: str, **overrides: float) -> ScanRequest:
    fields = dict(pan_min=-1.0, pan_max=1.0, tilt_min=-0.4, tilt_max=0.4, speed=0.5,
                  tilt_step=0.2, dwell=0.0)
    fields.update(overrides)
    return ScanRequest(pattern=pattern, **fields)


PATTERNS = ('sector', 'zigzag', 'square')


def test_sector_keeps_current_tilt() -> None:
    points = plan_scan(scan('sector'), ['pan', 'tilt'], {'pan': 0, 'tilt': 0.3}, LIMITS, PATTERNS)
    assert points == [{'pan': -1.0, 'tilt': 0.3}, {'pan': 1.0, 'tilt': 0.3}]


def test_zigzag_rows_alternate() -> None:
    points = plan_scan(scan('zigzag'), ['pan', 'tilt'], {}, LIMITS, PATTERNS)
    assert len(points) == 10
    assert points[0] == {'pan': -1.0, 'tilt': -0.4} and points[2]['pan'] == 1.0
    assert points[-1]['tilt'] == pytest.approx(0.4)


def test_square_shrinks_inward() -> None:
    points = plan_scan(scan('square'), ['pan', 'tilt'], {}, LIMITS, PATTERNS)
    assert points[:4] == [{'pan': -1.0, 'tilt': 0.4}, {'pan': 1.0, 'tilt': 0.4},
                          {'pan': 1.0, 'tilt': -0.4}, {'pan': -1.0, 'tilt': -0.4}]
    assert points[4]['pan'] == pytest.approx(-0.8)


@pytest.mark.parametrize(
    ('request_', 'message'),
    [
        (scan('snake'), "pattern 'snake' not available"),
        (scan('sector', speed=0.0), 'speed 0.0 must be > 0'),
        (scan('sector', speed=2.0), 'exceeds pan velocity_max'),
        (scan('sector', pan_min=-4.0), 'outside the joint limits'),
        (scan('zigzag', tilt_step=0.0), 'tilt_step'),
        (scan('zigzag', tilt_min=0.5, tilt_max=0.1), 'tilt_min'),
        (scan('sector', dwell=-1.0), 'dwell'),
    ],
)
def test_scan_rejections(request_, message) -> None:
    with pytest.raises(ScanError, match=message):
        plan_scan(request_, ['pan', 'tilt'], {'pan': 0.0, 'tilt': 0.0}, LIMITS, PATTERNS)


def test_domain_leases_are_exclusive_and_not_reused_at_once() -> None:
    """A held id is never handed out twice; a just-released id is not the next one leased."""
    from gimbal_driver_testing import DomainLease

    with DomainLease() as first, DomainLease() as second:
        assert first != second
    with DomainLease() as third:
        assert third not in (first, second)
