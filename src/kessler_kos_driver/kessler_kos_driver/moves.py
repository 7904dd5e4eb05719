"""Turning ROS-level move requests into kOS trajectories (pure Python, no ROS).

Joint positions are SI (rad or m); the device works in motor rotations, converted by each
joint's :class:`~kessler_kos_driver.units.JointUnits` at the axis' calibration (its span over
the end mark, or joint_scales). Bezier segments are normalised: time as a fraction of the
move, position as a fraction of the calibrated range (0 = BeginPosition, 1 = EndPosition).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from .protocol import (
    DelayMode,
    PlaybackBlock,
    PlaybackMode,
    SegmentBlock,
    TimeLapseBlock,
    Trajectory,
    TrajectoryError,
    fit_keyframes,
)
from .protocol.trajectory import LOOP_FOREVER
from .units import Conversion, JointUnits


@dataclass(frozen=True)
class JointMapping:
    name: str
    address: int
    units: JointUnits = field(default_factory=JointUnits)   # SI <-> rotations


@dataclass(frozen=True)
class AxisRange:
    begin: float              # rotations
    end: float                # rotations; == begin means uncalibrated

    def normalise(self, rotations: float) -> float:
        return (rotations - self.begin) / (self.end - self.begin)

    def rotations(self, normalised: float) -> float:
        return self.begin + normalised * (self.end - self.begin)

    def conversion(self, units: JointUnits) -> Conversion:
        """The joint's SI conversion at this calibration."""
        return units.conversion(self.end)


@dataclass
class PlaybackSettings:
    mode: int = PlaybackMode.LIVE_MOTION
    duration: float = 0.0         # s; 0 = the last keyframe's time
    loop_count: int = 0           # 0 once, 255 forever
    rapid_reverse: bool = False
    start_delay: float = 0.0      # s (DelayMode 1)
    start_time: int = 0           # UnixTime s to start at (DelayMode 2); 0 = not used
    interval: float = 0.0         # time lapse Delay, s
    exposure: float = 0.0         # s
    move_photos: int = 0
    pre_move_photos: int = 0
    post_move_photos: int = 0
    return_to_home_percent: float = 100.0


@dataclass
class Keyframe:
    time: float                                  # s from the start of the move
    positions: dict[str, float]                  # joint -> SI position
    velocities: dict[str, float] | None = None   # joint -> SI velocity


def _blocks(settings: PlaybackSettings, duration: float) -> tuple[PlaybackBlock, TimeLapseBlock]:
    if settings.mode not in tuple(PlaybackMode):
        raise TrajectoryError(f'playback_mode {settings.mode} is not 0 (live motion), '
                              '1 (time lapse continuous) or 2 (time lapse SMS)')
    if not 0 <= settings.loop_count <= LOOP_FOREVER:
        raise TrajectoryError('loop_count must be 0..255 (255 = forever)')
    if not math.isfinite(settings.start_delay) or settings.start_delay < 0:
        raise TrajectoryError(f'start_delay must be >= 0 s, got {settings.start_delay}')
    delay_mode, delay_interval = DelayMode.NONE, 0.0
    if settings.start_time:
        if settings.start_delay > 0:
            raise TrajectoryError('give start_delay (s) or start_time (date), not both')
        if not 0 < settings.start_time <= 0xFFFFFFFF:
            raise TrajectoryError(f'start_time must be a UnixTime in 1..4294967295 s, got '
                                  f'{settings.start_time}')
        delay_mode, delay_interval = DelayMode.UNTIL_DATE, float(settings.start_time)
    elif settings.start_delay > 0:
        delay_mode, delay_interval = DelayMode.FOR_TIME, settings.start_delay
    playback = PlaybackBlock(
        playback_mode=settings.mode,
        duration=duration,
        rapid_reverse_duration=duration,      # document: "set to the same value as Duration"
        loop_after_rapid_reverse=settings.loop_count if settings.rapid_reverse else 0,
        loop_after_reverse=0 if settings.rapid_reverse else settings.loop_count,
        delay_mode=delay_mode,
        delay_interval=delay_interval,
        return_to_home_percent=settings.return_to_home_percent,
    )
    timelapse = TimeLapseBlock()
    if settings.mode != PlaybackMode.LIVE_MOTION:
        timelapse = TimeLapseBlock(settings.interval, settings.exposure, settings.move_photos,
                                   0, settings.pre_move_photos, settings.post_move_photos)
        if settings.mode == PlaybackMode.TIMELAPSE_CONTINUOUS:
            playback.duration = playback.rapid_reverse_duration = (
                settings.move_photos * (settings.interval + settings.exposure))
    return playback, timelapse


def _mapping(joint: str, joints: Mapping[str, JointMapping]) -> JointMapping:
    mapping = joints.get(joint)
    if mapping is None:
        raise TrajectoryError(f'unknown joint {joint!r}; known joints: '
                              f'{", ".join(sorted(joints))}')
    return mapping


def _range(mapping: JointMapping, ranges: Mapping[int, AxisRange]) -> AxisRange:
    axis = ranges.get(mapping.address)
    if axis is None:
        raise TrajectoryError(f'joint {mapping.name!r} (motor {mapping.address}) is not '
                              'connected')
    if axis.end == axis.begin:
        raise TrajectoryError(f'joint {mapping.name!r} (motor {mapping.address}) is not '
                              'calibrated; mark its begin and end first (~/calibrate)')
    return axis


def from_keyframes(
    keyframes: Sequence[Keyframe],
    joints: Mapping[str, JointMapping],
    ranges: Mapping[int, AxisRange],
    settings: PlaybackSettings,
) -> Trajectory:
    """Fit Bezier segments through SI keyframes, one axis per joint that appears."""
    if not keyframes:
        raise TrajectoryError('no keyframes given')
    times = [k.time for k in keyframes]
    if any(not math.isfinite(t) or t < 0 for t in times):
        raise TrajectoryError('keyframe times (time_from_start) must be finite and >= 0')
    for index in range(1, len(times)):
        if times[index] <= times[index - 1]:
            raise TrajectoryError(f'keyframe {index}: time_from_start must be strictly '
                                  'increasing')
    duration = settings.duration if settings.duration > 0 else times[-1]
    if duration <= 0:
        raise TrajectoryError('the move has no length: give a duration or keyframes with '
                              'time_from_start > 0')
    if times[-1] > duration + 1e-9:
        raise TrajectoryError(f'the last keyframe at {times[-1]:.3f} s is after the end of the '
                              f'move ({duration:.3f} s)')
    names = list(keyframes[0].positions)
    for index, keyframe in enumerate(keyframes):
        if sorted(keyframe.positions) != sorted(names):
            raise TrajectoryError(f'keyframe {index} does not give a position for every joint')
    axes: dict[int, list[SegmentBlock]] = {}
    for name in names:
        mapping = _mapping(name, joints)
        axis = _range(mapping, ranges)
        units = axis.conversion(mapping.units)
        normalised = []
        for index, keyframe in enumerate(keyframes):
            value = keyframe.positions[name]
            if not math.isfinite(value):
                raise TrajectoryError(f'keyframe {index}: joint {name!r} position is not finite')
            normalised.append(axis.normalise(units.to_rotations(value)))
        for index, value in enumerate(normalised):
            if not -1e-9 <= value <= 1 + 1e-9:
                low, high = sorted((units.to_si(axis.begin), units.to_si(axis.end)))
                raise TrajectoryError(
                    f'keyframe {index}: joint {name!r} position '
                    f'{keyframes[index].positions[name]:.4f} is outside its calibrated range '
                    f'[{low:.4f}, {high:.4f}]')
        normalised = [min(max(v, 0.0), 1.0) for v in normalised]
        velocities = None
        if any(k.velocities for k in keyframes):
            span = axis.end - axis.begin
            velocities = [units.rate_to_rotations((k.velocities or {}).get(name, 0.0))
                          / span * duration for k in keyframes]
        try:
            fitted = fit_keyframes([t / duration for t in times], normalised, velocities)
        except TrajectoryError as exc:
            raise TrajectoryError(f'joint {name!r}: {exc}') from exc
        axes[mapping.address] = [
            SegmentBlock(mapping.address, i, ts[0], ps[0], ts[1], ps[1], ts[2], ps[2], ts[3],
                         ps[3])
            for i, (ts, ps) in enumerate(fitted)
        ]
    playback, timelapse = _blocks(settings, duration)
    return Trajectory(playback, timelapse, axes)


def from_segments(
    segments: Mapping[str, Sequence[Sequence[float]]],
    joints: Mapping[str, JointMapping],
    settings: PlaybackSettings,
) -> Trajectory:
    """Explicit per-joint Bezier segments (8 normalised numbers each), accepted as they are."""
    if not segments:
        raise TrajectoryError('no axes given')
    if settings.mode == PlaybackMode.LIVE_MOTION and settings.duration <= 0:
        raise TrajectoryError('explicit segments need a duration > 0 s (live motion)')
    axes: dict[int, list[SegmentBlock]] = {}
    for name, points in segments.items():
        mapping = _mapping(name, joints)
        if mapping.address in axes:
            raise TrajectoryError(f'joint {name!r} is given twice')
        axes[mapping.address] = [SegmentBlock(mapping.address, i, *map(float, p))
                                 for i, p in enumerate(points)]
    playback, timelapse = _blocks(settings, settings.duration)
    return Trajectory(playback, timelapse, axes)
