"""SI keyframes -> kOS trajectory conversion (moves.py), no device involved."""

import math

import pytest

from kessler_kos_driver.moves import (
    AxisRange,
    JointMapping,
    Keyframe,
    PlaybackSettings,
    from_keyframes,
    from_segments,
)
from kessler_kos_driver.protocol import (
    DelayMode,
    PlaybackMode,
    TrajectoryError,
    position_at,
    validate,
)
from kessler_kos_driver.units import JointUnits

JOINTS = {'pan': JointMapping('pan', 2, JointUnits(scale=-2 * math.pi)),
          'tilt': JointMapping('tilt', 3, JointUnits(scale=0.5))}
RANGES = {2: AxisRange(0.0, 100.0), 3: AxisRange(0.0, -40.0)}


def curve(traj, address):
    return [(s.times, s.positions) for s in traj.axes[address]]


def test_normalisation_with_negative_scale_and_negative_range():
    keyframes = [Keyframe(1.0, {'pan': -2 * math.pi * 10, 'tilt': -5.0}),
                 Keyframe(5.0, {'pan': -2 * math.pi * 60, 'tilt': -15.0})]
    traj = from_keyframes(keyframes, JOINTS, RANGES, PlaybackSettings(duration=8.0))
    validate(traj)
    assert traj.playback.duration == 8.0 == traj.playback.rapid_reverse_duration
    # pan: -20*pi rad / (-2*pi rad/rot) = 10 rot = 0.1 of the 0..100 range
    assert position_at(curve(traj, 2), 1 / 8) == pytest.approx(0.1)
    assert position_at(curve(traj, 2), 5 / 8) == pytest.approx(0.6)
    # tilt: -5 / 0.5 = -10 rot = 0.25 of the 0..-40 range; hold before and after
    assert position_at(curve(traj, 3), 0.0) == pytest.approx(0.25)
    assert position_at(curve(traj, 3), 1.0) == pytest.approx(0.75)
    assert len(traj.axes[3]) == 3


def test_velocities_are_scaled_to_normalised_units():
    keyframes = [Keyframe(0.0, {'tilt': 0.0}, {'tilt': 0.0}),
                 Keyframe(2.0, {'tilt': -10.0}, {'tilt': -2.0}),
                 Keyframe(4.0, {'tilt': -10.0}, {'tilt': 0.0})]
    traj = from_keyframes(keyframes, JOINTS, RANGES, PlaybackSettings())
    first = traj.axes[3][0]
    # -2 (SI/s) / 0.5 (SI/rot) / -40 (rot range) * 4 s = 0.4 normalised per normalised time
    slope_at_end = (first.p3_position - first.p2_position) / (first.p3_time - first.p2_time)
    assert slope_at_end == pytest.approx(0.4)


def test_settings_map_to_the_playback_block():
    keyframes = [Keyframe(0.0, {'pan': 0.0}), Keyframe(3.0, {'pan': -1.0})]
    traj = from_keyframes(keyframes, JOINTS, RANGES,
                          PlaybackSettings(loop_count=3, rapid_reverse=True, start_delay=2.5))
    pb = traj.playback
    assert (pb.loop_after_rapid_reverse, pb.loop_after_reverse) == (3, 0)
    assert (pb.delay_mode, pb.delay_interval) == (DelayMode.FOR_TIME, 2.5)
    traj = from_keyframes(keyframes, JOINTS, RANGES, PlaybackSettings(
        mode=PlaybackMode.TIMELAPSE_CONTINUOUS, interval=1.5, exposure=0.5, move_photos=10,
        pre_move_photos=1, post_move_photos=2))
    assert traj.effective_duration() == 20.0
    tl = traj.timelapse
    assert (tl.delay, tl.exposure, tl.move_photos, tl.pre_move_photos, tl.post_move_photos) == \
        (1.5, 0.5, 10, 1, 2)
    validate(traj)


@pytest.mark.parametrize('keyframes, ranges, message', [
    ([Keyframe(0, {'roll': 0.0}), Keyframe(1, {'roll': 1.0})], RANGES, 'unknown joint'),
    ([Keyframe(0, {'pan': 0.0}), Keyframe(1, {'pan': 1.0})], RANGES, 'calibrated range'),
    ([Keyframe(0, {'pan': 0.0}), Keyframe(1, {'pan': -1.0})], {2: AxisRange(0, 0)},
     'not calibrated'),
    ([Keyframe(0, {'pan': 0.0}), Keyframe(1, {'pan': -1.0})], {}, 'not connected'),
    ([Keyframe(0, {'pan': 0.0}), Keyframe(1, {'tilt': -1.0})], RANGES, 'every joint'),
    ([Keyframe(0, {'pan': 0.0})], RANGES, 'no length'),
    ([Keyframe(0, {'pan': 0.0}), Keyframe(2, {'pan': -1.0}), Keyframe(1, {'pan': -1.0})],
     RANGES, 'strictly increasing'),
    ([Keyframe(0, {'pan': math.nan}), Keyframe(1, {'pan': 0.0})], RANGES, 'not finite'),
    ([], RANGES, 'no keyframes'),
])
def test_bad_requests_are_refused(keyframes, ranges, message):
    with pytest.raises(TrajectoryError, match=message):
        from_keyframes(keyframes, JOINTS, ranges, PlaybackSettings())


def test_explicit_segments_need_a_duration_and_known_joints():
    segments = {'pan': [(0, 0, 1 / 3, 0, 2 / 3, 1, 1, 1)]}
    with pytest.raises(TrajectoryError, match='duration'):
        from_segments(segments, JOINTS, PlaybackSettings())
    with pytest.raises(TrajectoryError, match='unknown joint'):
        from_segments({'roll': segments['pan']}, JOINTS, PlaybackSettings(duration=1.0))
    traj = from_segments(segments, JOINTS, PlaybackSettings(duration=5.0))
    validate(traj)
    assert traj.axes[2][0].p3_position == 1.0


def test_start_time_is_delay_mode_2_with_a_unixtime():
    keyframes = [Keyframe(0.0, {'pan': 0.0}), Keyframe(2.0, {'pan': -2 * math.pi * 10})]
    traj = from_keyframes(keyframes, JOINTS, RANGES,
                          PlaybackSettings(start_time=1_900_000_000))
    assert traj.playback.delay_mode == DelayMode.UNTIL_DATE
    encoded = traj.playback.data()
    assert (1_900_000_000).to_bytes(4, 'big') in encoded   # UInt32, not a Float32
    with pytest.raises(TrajectoryError, match='not both'):
        from_keyframes(keyframes, JOINTS, RANGES,
                       PlaybackSettings(start_time=1_900_000_000, start_delay=1.0))
    with pytest.raises(TrajectoryError, match='UnixTime'):
        from_keyframes(keyframes, JOINTS, RANGES, PlaybackSettings(start_time=2**32))


def test_a_span_and_an_offset_normalise_through_the_end_mark():
    """Tilt: pi from -pi/2 (begin) to +pi/2 over 0..-40 rotations: SI maps straight onto
    the normalised range whatever the motor's direction."""
    joints = {'tilt': JointMapping('tilt', 3, JointUnits(span=math.pi, offset=-math.pi / 2))}
    keyframes = [Keyframe(0.0, {'tilt': -math.pi / 2}, {'tilt': 0.0}),
                 Keyframe(2.0, {'tilt': 0.0}, {'tilt': 0.5}),
                 Keyframe(4.0, {'tilt': math.pi / 4}, {'tilt': 0.0})]
    traj = from_keyframes(keyframes, joints, RANGES, PlaybackSettings())
    validate(traj)
    assert position_at(curve(traj, 3), 0.0) == pytest.approx(0.0)
    assert position_at(curve(traj, 3), 0.5) == pytest.approx(0.5)
    assert position_at(curve(traj, 3), 1.0) == pytest.approx(0.75)
    first = traj.axes[3][0]
    # 0.5 rad/s over a pi span, times the 4 s move: 2/pi normalised per normalised time
    slope_at_end = (first.p3_position - first.p2_position) / (first.p3_time - first.p2_time)
    assert slope_at_end == pytest.approx(2.0 / math.pi)
    with pytest.raises(TrajectoryError, match=r'outside its calibrated range \[-1.5708, 1.5708\]'):
        from_keyframes([Keyframe(0, {'tilt': 0.0}), Keyframe(1, {'tilt': 1.6})], joints,
                       RANGES, PlaybackSettings())
