"""Keyframe -> Bezier fitting properties."""

import itertools

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from kessler_kos_driver.protocol import TrajectoryError, fit_keyframes, position_at
from kessler_kos_driver.protocol.bezier import evaluate

unit = st.floats(0.0, 1.0, allow_nan=False)


@st.composite
def keyframes(draw, velocities=False):
    times = sorted(set(draw(st.lists(unit, min_size=1, max_size=12))))
    assume(all(b - a > 1e-4 for a, b in itertools.pairwise(times)))
    positions = draw(st.lists(unit, min_size=len(times), max_size=len(times)))
    vel = None
    if velocities:
        vel = draw(st.lists(st.floats(-20, 20), min_size=len(times), max_size=len(times)))
    return times, positions, vel


def samples(segments, per=16):
    for times, positions in segments:
        for i in range(per + 1):
            yield evaluate(times, positions, i / per)


@settings(max_examples=200, deadline=None)
@given(keyframes())
def test_passes_through_keyframes_monotone_time_and_no_overshoot(kf):
    times, positions, _ = kf
    segments = fit_keyframes(times, positions)
    assert segments[0][0][0] == 0.0 and segments[-1][0][3] == 1.0
    previous_end = 0.0
    for seg_times, seg_positions in segments:
        assert seg_times[0] == previous_end
        assert seg_times[0] <= seg_times[1] <= seg_times[2] <= seg_times[3]
        previous_end = seg_times[3]
        lo, hi = sorted((seg_positions[0], seg_positions[3]))
        # P1/P2 lie between the keyframes: the curve cannot overshoot them
        assert lo - 1e-12 <= seg_positions[1] <= hi + 1e-12
        assert lo - 1e-12 <= seg_positions[2] <= hi + 1e-12
    for t, p in zip(times, positions, strict=True):
        assert position_at(segments, t) == pytest.approx(p, abs=1e-9)
    last_t = -1.0
    for t, p in samples(segments):
        assert t >= last_t - 1e-12
        last_t = t
        assert -1e-12 <= p <= 1 + 1e-12


@settings(max_examples=200, deadline=None)
@given(keyframes(velocities=True))
def test_user_velocities_stay_within_range(kf):
    times, positions, velocities = kf
    segments = fit_keyframes(times, positions, velocities)
    for t, p in zip(times, positions, strict=True):
        assert position_at(segments, t) == pytest.approx(p, abs=1e-9)
    for _, p in samples(segments):
        assert -1e-12 <= p <= 1 + 1e-12


def test_smooth_interior_keyframe_has_matching_tangents():
    segments = fit_keyframes([0.0, 0.4, 1.0], [0.0, 0.5, 1.0])
    (t_a, p_a), (t_b, p_b) = segments
    slope_in = (p_a[3] - p_a[2]) / (t_a[3] - t_a[2])
    slope_out = (p_b[1] - p_b[0]) / (t_b[1] - t_b[0])
    assert slope_in == pytest.approx(slope_out) and slope_in > 0


@pytest.mark.parametrize('times, positions, message', [
    ([0.0, 0.5], [0.0, 1.2], 'calibrated range'),
    ([0.0, 1.5], [0.0, 0.2], 'outside the move'),
    ([0.0, 0.5, 0.5], [0.0, 0.2, 0.3], 'strictly increasing'),
    ([], [], 'at least one'),
])
def test_bad_keyframes_are_refused(times, positions, message):
    with pytest.raises(TrajectoryError, match=message):
        fit_keyframes(times, positions)
