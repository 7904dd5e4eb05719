"""TrajectoryData (message 0x12) and its blocks: Playback, TimeLapse, Axis, Segment.

Wire format: BlockCount (UInt8), then per block BlockID (UInt8) + Block (UInt16 length + data).

Reconstruction decisions (checked against the document's declared BlockSize values):
- Playback BlockSize 37 = 1+4+4+1+1+1+4+1+4+4+1+1+4+1+1+4 with the listed field types: consistent.
- TimeLapse BlockSize 21 = 4+4+4+1+4+4: consistent.
- Axis BlockSize 2 = MotorAddress + SegmentCount: consistent.
- Segment BlockSize 34: the OCR lists "P0Time P0Position P1Time P2Time P2Time P3Time P3Time
  P3Time"; 34 = 2 + 8 x Float32, i.e. four (time, position) control points, so the fields are
  P0Time, P0Position, P1Time, P1Position, P2Time, P2Position, P3Time, P3Position.
- DelayInterval is Float32 seconds for DelayMode 1, but for DelayMode 2 the document says it is
  a UnixTime (UInt32); a Float32 cannot hold a date to the second, so in mode 2 the same four
  bytes carry a UInt32.
- "The first three blocks must be included": only Playback (1) and TimeLapse (2) are defined
  before the Axis blocks (ids 3 and 4 are absent from the document), so a valid Set carries
  Playback and TimeLapse once each and at least one Axis block. Unknown block ids are kept as
  RawBlock on decode (round trip) and rejected by validate().
- Axis/Segment ordering: each Axis block is followed by its SegmentCount Segment blocks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

from .constants import (
    MOTOR_ADDRESS_MAX,
    MOTOR_ADDRESS_MIN,
    BlockId,
    DelayMode,
    MessageId,
    MessageType,
    PlaybackMode,
)
from .errors import DecodeError, EncodeError, TrajectoryError
from .messages import Message
from .wire import Reader, Writer

PLAYBACK_BLOCK_SIZE = 37
TIMELAPSE_BLOCK_SIZE = 21
AXIS_BLOCK_SIZE = 2
SEGMENT_BLOCK_SIZE = 34
LOOP_FOREVER = 255
MAX_BLOCKS = 255
CONTINUITY_TOLERANCE = 1e-4   # normalised units; float32 round-off is ~6e-8


@dataclass
class PlaybackBlock:
    BLOCK_ID: ClassVar[int] = BlockId.PLAYBACK
    playback_mode: int = PlaybackMode.LIVE_MOTION
    duration: float = 0.0                  # s
    rapid_reverse_duration: float = 0.0    # s; document: set equal to duration
    loop_after_rapid_reverse: int = 0      # 255 = forever
    loop_after_reverse: int = 0            # 255 = forever
    delay_mode: int = DelayMode.NONE
    delay_interval: float = 0.0            # s (mode 1) or UnixTime (mode 2)
    camera_roll_enabled: bool = False      # unsupported, must be 0
    camera_roll_pre_delay: float = 0.0     # must be 0
    camera_roll_post_delay: float = 0.0
    flash_mark_enabled: bool = False       # all FlashMark fields must be 0
    flash_mark_type: int = 0
    flash_mark_post_delay: float = 0.0
    use_external_trigger: bool = False     # unsupported, must be 0
    using_lanc_cable: bool = False         # unsupported, must be 0
    return_to_home_percent: float = 100.0  # speed of the return to the first key frame

    def data(self) -> bytes:
        w = Writer().u8(self.playback_mode, 'PlaybackMode').f32(self.duration, 'Duration')
        w.f32(self.rapid_reverse_duration, 'RapidReverseDuration')
        w.u8(self.loop_after_rapid_reverse, 'LoopAfterRapidReverse')
        w.u8(self.loop_after_reverse, 'LoopAfterReverse').u8(self.delay_mode, 'DelayMode')
        if self.delay_mode == DelayMode.UNTIL_DATE:
            w.u32(int(self.delay_interval), 'DelayInterval (UnixTime)')
        else:
            w.f32(self.delay_interval, 'DelayInterval')
        w.boolean(self.camera_roll_enabled).f32(self.camera_roll_pre_delay)
        w.f32(self.camera_roll_post_delay).boolean(self.flash_mark_enabled)
        w.u8(self.flash_mark_type, 'FlashMarkType').f32(self.flash_mark_post_delay)
        w.boolean(self.use_external_trigger).boolean(self.using_lanc_cable)
        return w.f32(self.return_to_home_percent, 'ReturnToHomePercent').getvalue()

    @classmethod
    def from_data(cls, r: Reader) -> PlaybackBlock:
        mode, duration, rapid = r.u8(), r.f32(), r.f32()
        loop_rapid, loop_reverse, delay_mode = r.u8(), r.u8(), r.u8()
        delay = float(r.u32()) if delay_mode == DelayMode.UNTIL_DATE else r.f32()
        return cls(mode, duration, rapid, loop_rapid, loop_reverse, delay_mode, delay,
                   r.boolean(), r.f32(), r.f32(), r.boolean(), r.u8(), r.f32(), r.boolean(),
                   r.boolean(), r.f32())


@dataclass
class TimeLapseBlock:
    BLOCK_ID: ClassVar[int] = BlockId.TIMELAPSE
    delay: float = 0.0          # s between photos (interval less exposure)
    exposure: float = 0.0       # s shutter open
    move_photos: int = 0
    not_used: int = 0           # "*Not Used*": must be 0
    pre_move_photos: int = 0
    post_move_photos: int = 0

    def data(self) -> bytes:
        w = Writer().f32(self.delay, 'Delay').f32(self.exposure, 'Exposure')
        w.u32(self.move_photos, 'MovePhotos').u8(self.not_used, 'NotUsed')
        w.u32(self.pre_move_photos, 'PreMovePhotos')
        return w.u32(self.post_move_photos, 'PostMovePhotos').getvalue()

    @classmethod
    def from_data(cls, r: Reader) -> TimeLapseBlock:
        return cls(r.f32(), r.f32(), r.u32(), r.u8(), r.u32(), r.u32())


@dataclass
class AxisBlock:
    BLOCK_ID: ClassVar[int] = BlockId.AXIS
    motor_address: int = 1
    segment_count: int = 0

    def data(self) -> bytes:
        w = Writer().u8(self.motor_address, 'MotorAddress')
        return w.u8(self.segment_count, 'SegmentCount').getvalue()

    @classmethod
    def from_data(cls, r: Reader) -> AxisBlock:
        return cls(r.u8(), r.u8())


@dataclass
class SegmentBlock:
    """One cubic Bezier in (normalised time, normalised position)."""

    BLOCK_ID: ClassVar[int] = BlockId.SEGMENT
    motor_address: int = 1
    segment_number: int = 0
    p0_time: float = 0.0
    p0_position: float = 0.0
    p1_time: float = 0.0
    p1_position: float = 0.0
    p2_time: float = 0.0
    p2_position: float = 0.0
    p3_time: float = 0.0
    p3_position: float = 0.0

    @property
    def times(self) -> tuple[float, float, float, float]:
        return (self.p0_time, self.p1_time, self.p2_time, self.p3_time)

    @property
    def positions(self) -> tuple[float, float, float, float]:
        return (self.p0_position, self.p1_position, self.p2_position, self.p3_position)

    def data(self) -> bytes:
        w = Writer().u8(self.motor_address, 'MotorAddress')
        w.u8(self.segment_number, 'SegmentNumber')
        for t, p in zip(self.times, self.positions, strict=True):
            w.f32(t, 'segment time').f32(p, 'segment position')
        return w.getvalue()

    @classmethod
    def from_data(cls, r: Reader) -> SegmentBlock:
        return cls(r.u8(), r.u8(), *(r.f32() for _ in range(8)))


@dataclass
class RawBlock:
    """A block id the document does not define; kept for round trips, refused by validate."""

    block_id: int
    raw: bytes

    def data(self) -> bytes:
        return self.raw


Block = PlaybackBlock | TimeLapseBlock | AxisBlock | SegmentBlock | RawBlock
_BLOCK_TYPES: dict[int, tuple[type[PlaybackBlock] | type[TimeLapseBlock] | type[AxisBlock]
                               | type[SegmentBlock], int]] = {
    BlockId.PLAYBACK: (PlaybackBlock, PLAYBACK_BLOCK_SIZE),
    BlockId.TIMELAPSE: (TimeLapseBlock, TIMELAPSE_BLOCK_SIZE),
    BlockId.AXIS: (AxisBlock, AXIS_BLOCK_SIZE),
    BlockId.SEGMENT: (SegmentBlock, SEGMENT_BLOCK_SIZE),
}


def block_id(block: Block) -> int:
    return block.block_id if isinstance(block, RawBlock) else block.BLOCK_ID


@dataclass
class TrajectoryData(Message):
    """(Set)TrajectoryData or TrajectoryData(Response): a list of blocks."""

    MESSAGE_ID: ClassVar[int] = MessageId.TRAJECTORY_DATA
    blocks: list[Block] = field(default_factory=list)
    message_type: int = MessageType.SET

    def payload(self) -> bytes:
        if len(self.blocks) > MAX_BLOCKS:
            raise EncodeError(f'{len(self.blocks)} blocks; BlockCount (UInt8) allows 255')
        w = Writer().u8(len(self.blocks), 'BlockCount')
        for block in self.blocks:
            w.u8(block_id(block), 'BlockID').block(block.data(), 'TrajectoryData block')
        return w.getvalue()

    def encode(self) -> bytes:
        from .framing import encode_frame
        return encode_frame(self.MESSAGE_ID, int(self.message_type), self.payload())

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> TrajectoryData:
        count = reader.u8('BlockCount')
        blocks: list[Block] = []
        for index in range(count):
            bid = reader.u8('BlockID')
            data = reader.block(f'block {index}')
            known = _BLOCK_TYPES.get(bid)
            if known is None:
                blocks.append(RawBlock(bid, data))
                continue
            block_cls, size = known
            if len(data) != size:
                raise DecodeError(
                    f'block {index} (id {bid}) is {len(data)} bytes, BlockSize must be {size}'
                )
            sub = Reader(data, block_cls.__name__)
            blocks.append(block_cls.from_data(sub))
        return cls(blocks, message_type)


# ---------------------------------------------------------------- high-level trajectory
@dataclass
class AxisLimits:
    """What validate() needs to know about one motor (rotations based)."""

    begin_position: float
    end_position: float
    max_move_speed: float
    max_acceleration: float


@dataclass
class Trajectory:
    """A move as the document structures it: settings plus per-axis Bezier segments."""

    playback: PlaybackBlock
    timelapse: TimeLapseBlock
    axes: dict[int, list[SegmentBlock]]

    def to_message(self) -> TrajectoryData:
        blocks: list[Block] = [self.playback, self.timelapse]
        for address, segments in self.axes.items():
            blocks.append(AxisBlock(address, len(segments)))
            blocks.extend(segments)
        return TrajectoryData(blocks, MessageType.SET)

    @classmethod
    def from_message(cls, message: TrajectoryData) -> Trajectory:
        """Group blocks; raises TrajectoryError if the structure is wrong."""
        playback = timelapse = None
        axes: dict[int, list[SegmentBlock]] = {}
        expected: dict[int, int] = {}
        current: int | None = None
        for block in message.blocks:
            if isinstance(block, RawBlock):
                raise TrajectoryError(f'unknown TrajectoryData block id {block.block_id}')
            if isinstance(block, PlaybackBlock):
                if playback is not None:
                    raise TrajectoryError('more than one Playback block')
                playback = block
            elif isinstance(block, TimeLapseBlock):
                if timelapse is not None:
                    raise TrajectoryError('more than one TimeLapse block')
                timelapse = block
            elif isinstance(block, AxisBlock):
                if block.motor_address in axes:
                    raise TrajectoryError(f'two Axis blocks for motor {block.motor_address}')
                axes[block.motor_address] = []
                expected[block.motor_address] = block.segment_count
                current = block.motor_address
            else:
                if current is None:
                    raise TrajectoryError('Segment block before any Axis block')
                if block.motor_address != current:
                    raise TrajectoryError(
                        f'Segment for motor {block.motor_address} inside the Axis block of '
                        f'motor {current}'
                    )
                axes[current].append(block)
        if playback is None or timelapse is None:
            raise TrajectoryError('Playback and TimeLapse blocks are both required')
        for address, count in expected.items():
            if len(axes[address]) != count:
                raise TrajectoryError(
                    f'motor {address}: Axis block announces {count} segments, '
                    f'{len(axes[address])} follow'
                )
        return cls(playback, timelapse, axes)

    def effective_duration(self) -> float:
        """Seconds the trajectory's time 0..1 spans during playback (0 if event driven)."""
        mode = self.playback.playback_mode
        if mode == PlaybackMode.LIVE_MOTION:
            return self.playback.duration
        if mode == PlaybackMode.TIMELAPSE_CONTINUOUS:
            tl = self.timelapse
            return tl.move_photos * (tl.delay + tl.exposure)
        return 0.0   # SMS: steps between photos, each at the motor's own speed

    def validate(self, limits: dict[int, AxisLimits] | None = None) -> None:
        validate(self, limits)


def _finite(value: float, name: str) -> None:
    if not math.isfinite(value):
        raise TrajectoryError(f'{name} must be finite, got {value}')


def validate(traj: Trajectory, limits: dict[int, AxisLimits] | None = None) -> None:
    """Check the document's rules; raise TrajectoryError naming the first broken rule."""
    from .bezier import segment_peak_rates

    pb, tl = traj.playback, traj.timelapse
    try:
        mode = PlaybackMode(pb.playback_mode)
    except ValueError:
        raise TrajectoryError(f'PlaybackMode {pb.playback_mode} is not 0, 1 or 2') from None
    for name in ('duration', 'rapid_reverse_duration', 'delay_interval',
                 'return_to_home_percent'):
        _finite(getattr(pb, name), name)
    if pb.loop_after_reverse and pb.loop_after_rapid_reverse:
        raise TrajectoryError(
            'LoopAfterReverse and LoopAfterRapidReverse are mutually exclusive; set only one'
        )
    if mode != PlaybackMode.LIVE_MOTION and (pb.loop_after_reverse or
                                             pb.loop_after_rapid_reverse):
        raise TrajectoryError('looping (and reverse) is not supported in a time lapse move')
    if pb.delay_mode not in tuple(DelayMode):
        raise TrajectoryError(f'DelayMode {pb.delay_mode} is not 0, 1 or 2')
    if pb.delay_mode == DelayMode.NONE and pb.delay_interval != 0:
        raise TrajectoryError('DelayInterval must be 0 when DelayMode is 0 (no delay)')
    if pb.delay_interval < 0:
        raise TrajectoryError(f'DelayInterval must be >= 0, got {pb.delay_interval}')
    unused = {
        'CameraRollEnabled': pb.camera_roll_enabled,
        'CameraRollPreDelay': pb.camera_roll_pre_delay,
        'CameraRollPostDelay': pb.camera_roll_post_delay,
        'FlashMarkEnabled': pb.flash_mark_enabled,
        'FlashMarkType': pb.flash_mark_type,
        'FlashMarkPostDelay': pb.flash_mark_post_delay,
        'UseExternalTrigger': pb.use_external_trigger,
        'UsingLANCCable': pb.using_lanc_cable,
        'TimeLapse NotUsed': tl.not_used,
    }
    for name, value in unused.items():
        if value:
            raise TrajectoryError(f'{name} is unsupported/unused and must be 0, got {value}')
    if not 0.0 < pb.return_to_home_percent <= 100.0:
        raise TrajectoryError(
            f'ReturnToHomePercent must be in (0, 100], got {pb.return_to_home_percent}'
        )
    if mode == PlaybackMode.LIVE_MOTION:
        if pb.duration <= 0:
            raise TrajectoryError(f'Duration must be > 0 s for a live motion move, '
                                  f'got {pb.duration}')
        if pb.loop_after_rapid_reverse and pb.rapid_reverse_duration <= 0:
            raise TrajectoryError('RapidReverseDuration must be > 0 when looping with a '
                                  'rapid reverse')
    else:
        _finite(tl.delay, 'Delay')
        _finite(tl.exposure, 'Exposure')
        if tl.delay < 0 or tl.exposure < 0:
            raise TrajectoryError('time lapse Delay and Exposure must be >= 0 s')
        if tl.move_photos < 1:
            raise TrajectoryError('a time lapse needs MovePhotos >= 1')
        if mode == PlaybackMode.TIMELAPSE_CONTINUOUS and tl.delay + tl.exposure <= 0:
            raise TrajectoryError('a continuous time lapse needs Delay + Exposure > 0 s')
    if not traj.axes:
        raise TrajectoryError('a move needs at least one Axis block')
    if 2 + len(traj.axes) + sum(len(s) for s in traj.axes.values()) > MAX_BLOCKS:
        raise TrajectoryError('too many blocks: BlockCount (UInt8) allows 255 in total')
    duration = traj.effective_duration()
    for address, segments in traj.axes.items():
        _validate_axis(address, segments)
        if limits is None:
            continue
        if address not in limits:
            raise TrajectoryError(f'motor {address} is not connected')
        lim = limits[address]
        if lim.end_position == lim.begin_position:
            raise TrajectoryError(f'motor {address} is not calibrated (EndPosition 0); '
                                  'calibrate it before playing a move')
        if duration > 0:
            span = abs(lim.end_position - lim.begin_position)
            for seg in segments:
                speed, accel = segment_peak_rates(seg.times, seg.positions)
                speed_rot = speed * span / duration
                accel_rot = accel * span / duration**2
                if speed_rot > lim.max_move_speed * (1 + 1e-6):
                    raise TrajectoryError(
                        f'motor {address} segment {seg.segment_number}: peak speed '
                        f'{speed_rot:.3f} rot/s exceeds MaxMaxMoveSpeed '
                        f'{lim.max_move_speed:.3f}; lengthen the move'
                    )
                if accel_rot > lim.max_acceleration * (1 + 1e-6):
                    raise TrajectoryError(
                        f'motor {address} segment {seg.segment_number}: peak acceleration '
                        f'{accel_rot:.3f} rot/s^2 exceeds MaxMaxAcceleration '
                        f'{lim.max_acceleration:.3f}; lengthen the move or smooth it'
                    )


def _validate_axis(address: int, segments: list[SegmentBlock]) -> None:
    if not MOTOR_ADDRESS_MIN <= address <= MOTOR_ADDRESS_MAX:
        raise TrajectoryError(f'motor address {address} is outside 1..10')
    if not segments:
        raise TrajectoryError(f'motor {address}: an axis needs at least one segment')
    if len(segments) > 255:
        raise TrajectoryError(f'motor {address}: SegmentCount (UInt8) allows 255')
    tol = CONTINUITY_TOLERANCE
    for index, seg in enumerate(segments):
        where = f'motor {address} segment {index}'
        if seg.segment_number != index:
            raise TrajectoryError(f'{where}: SegmentNumber is {seg.segment_number}, '
                                  f'expected {index} (0-based, in order)')
        for value in seg.times + seg.positions:
            _finite(value, where)
        if any(not -tol <= v <= 1 + tol for v in seg.times + seg.positions):
            raise TrajectoryError(f'{where}: times and positions are normalised, must be '
                                  'within 0..1')
        t0, t1, t2, t3 = seg.times
        if not (t0 <= t1 + tol and t1 <= t2 + tol and t2 <= t3 + tol and t0 < t3):
            raise TrajectoryError(f'{where}: control point times must be increasing '
                                  f'(got {seg.times})')
        if index == 0 and abs(t0) > tol:
            raise TrajectoryError(f'{where}: the first segment must start at time 0')
        if index > 0:
            prev = segments[index - 1]
            if abs(prev.p3_time - t0) > tol or abs(prev.p3_position - seg.p0_position) > tol:
                raise TrajectoryError(f'{where}: does not start where segment {index - 1} '
                                      'ends')
    if abs(segments[-1].p3_time - 1.0) > tol:
        raise TrajectoryError(f'motor {address}: the last segment must end at time 1')
