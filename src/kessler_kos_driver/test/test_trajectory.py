"""TrajectoryData blocks: sizes, structure and the document's validation rules."""

import pytest

from kessler_kos_driver.protocol import (
    AxisLimits,
    DecodeError,
    PlaybackBlock,
    PlaybackMode,
    SegmentBlock,
    TimeLapseBlock,
    Trajectory,
    TrajectoryData,
    TrajectoryError,
    decode,
    fit_keyframes,
)
from kessler_kos_driver.protocol.trajectory import (
    AXIS_BLOCK_SIZE,
    PLAYBACK_BLOCK_SIZE,
    SEGMENT_BLOCK_SIZE,
    TIMELAPSE_BLOCK_SIZE,
)


def segments_for(address, keyframes):
    times = [t for t, _ in keyframes]
    positions = [p for _, p in keyframes]
    return [SegmentBlock(address, i, *sum(zip(ts, ps, strict=True), ()))
            for i, (ts, ps) in enumerate(fit_keyframes(times, positions))]


def live_move(**playback):
    settings = dict(playback_mode=PlaybackMode.LIVE_MOTION, duration=10.0,
                    rapid_reverse_duration=10.0)
    settings.update(playback)
    pb = PlaybackBlock(**settings)
    return Trajectory(pb, TimeLapseBlock(), {
        1: segments_for(1, [(0, 0.0), (0.5, 0.8), (1, 0.2)]),
        2: segments_for(2, [(0, 0.5), (1, 0.5)]),
        3: segments_for(3, [(0, 1.0), (0.3, 0.0), (1, 0.6)]),
    })


LIMITS = {a: AxisLimits(0.0, 100.0, 165.0, 100.0) for a in (1, 2, 3)}


def test_documented_block_sizes_match_the_encoders():
    assert len(PlaybackBlock().data()) == PLAYBACK_BLOCK_SIZE == 37
    assert len(TimeLapseBlock().data()) == TIMELAPSE_BLOCK_SIZE == 21
    assert len(SegmentBlock().data()) == SEGMENT_BLOCK_SIZE == 34
    assert AXIS_BLOCK_SIZE == 2


def test_message_round_trip_and_grouping():
    move = live_move()
    move.validate(LIMITS)
    message = move.to_message()
    frame = message.encode()
    assert frame[3:5] == b'\x00\x12' and frame[5] == 0  # MessageID 0x12, type Set
    decoded = decode(frame)
    assert isinstance(decoded, TrajectoryData)
    regrouped = Trajectory.from_message(decoded)
    assert sorted(regrouped.axes) == [1, 2, 3]
    assert [s.segment_number for s in regrouped.axes[3]] == [0, 1]
    regrouped.validate(LIMITS)


def test_wrong_block_size_is_a_decode_error():
    frame = bytearray(TrajectoryData([TimeLapseBlock()]).encode())
    frame[8] = 20  # BlockSize 21 -> 20
    with pytest.raises(DecodeError):
        decode(bytes(frame[:-1]))


def test_delay_until_date_uses_unixtime_bits():
    pb = PlaybackBlock(delay_mode=2, delay_interval=1_700_000_123.0)
    data = pb.data()
    assert data[12:16] == (1_700_000_123).to_bytes(4, 'big')
    decoded = decode(TrajectoryData([pb]).encode()).blocks[0]
    assert decoded.delay_interval == 1_700_000_123.0


@pytest.mark.parametrize('change, message', [
    (dict(loop_after_reverse=1, loop_after_rapid_reverse=2), 'mutually exclusive'),
    (dict(camera_roll_enabled=True), 'CameraRollEnabled'),
    (dict(flash_mark_type=1), 'FlashMarkType'),
    (dict(using_lanc_cable=True), 'UsingLANCCable'),
    (dict(delay_interval=3.0), 'DelayInterval must be 0'),
    (dict(return_to_home_percent=0.0), 'ReturnToHomePercent'),
    (dict(playback_mode=7), 'PlaybackMode'),
])
def test_playback_rules(change, message):
    move = live_move(**change)
    with pytest.raises(TrajectoryError, match=message):
        move.validate()


def test_time_lapse_rejects_loops_and_unused_field():
    move = live_move(loop_after_reverse=1)
    move.playback.playback_mode = PlaybackMode.TIMELAPSE_SMS
    move.timelapse = TimeLapseBlock(1.0, 0.1, 10)
    with pytest.raises(TrajectoryError, match='time lapse'):
        move.validate()
    move.playback.loop_after_reverse = 0
    move.validate()
    move.timelapse.not_used = 1
    with pytest.raises(TrajectoryError, match='NotUsed'):
        move.validate()
    move.timelapse = TimeLapseBlock(1.0, 0.1, 0)
    with pytest.raises(TrajectoryError, match='MovePhotos'):
        move.validate()


def test_speed_and_acceleration_limits():
    move = live_move()
    slow = {a: AxisLimits(0.0, 100.0, 5.0, 100.0) for a in (1, 2, 3)}
    with pytest.raises(TrajectoryError, match='MaxMaxMoveSpeed'):
        move.validate(slow)
    soft = {a: AxisLimits(0.0, 100.0, 165.0, 1.0) for a in (1, 2, 3)}
    with pytest.raises(TrajectoryError, match='MaxMaxAcceleration'):
        move.validate(soft)
    move.playback.duration = 1000.0
    move.validate(slow)


def test_uncalibrated_or_missing_motor():
    move = live_move()
    limits = dict(LIMITS)
    limits[2] = AxisLimits(0.0, 0.0, 165.0, 100.0)
    with pytest.raises(TrajectoryError, match='not calibrated'):
        move.validate(limits)
    del limits[2]
    with pytest.raises(TrajectoryError, match='not connected'):
        move.validate(limits)


def test_segment_structure_rules():
    move = live_move()
    move.axes[1][1].segment_number = 5
    with pytest.raises(TrajectoryError, match='SegmentNumber'):
        move.validate()
    move = live_move()
    move.axes[1][1].p0_position += 0.1
    with pytest.raises(TrajectoryError, match='does not start'):
        move.validate()
    move = live_move()
    move.axes[1][-1].p3_time = 0.9
    with pytest.raises(TrajectoryError, match='end at time 1'):
        move.validate()
    move = live_move()
    move.axes[2][0].p1_position = 1.5
    with pytest.raises(TrajectoryError, match=r'within 0\.\.1'):
        move.validate()
    move = live_move()
    seg = move.axes[2][0]
    seg.p1_time, seg.p2_time = seg.p2_time, seg.p1_time
    with pytest.raises(TrajectoryError, match='increasing'):
        move.validate()


def test_from_message_structure_errors():
    move = live_move()
    message = move.to_message()
    message.blocks.pop()  # last segment of motor 3 missing
    with pytest.raises(TrajectoryError, match='announces'):
        Trajectory.from_message(message)
    with pytest.raises(TrajectoryError, match='required'):
        Trajectory.from_message(TrajectoryData(message.blocks[1:]))
