"""Validate joint commands against per-joint limits before anything is sent.

``joint_command`` (sensor_msgs/JointState) and the MoveTo action carry names
with positions and/or velocities. This module turns them into a
:class:`CommandPlan` of absolute moves and jogs, or rejects the whole command
with a :class:`CommandError` naming the joint, the value and the limit, so a
bad command never reaches the device half-applied.

NaN means "no command for this joint" in a ``joint_command`` (docs/interface.md):
ros2_control's topic hardware interface sends NaN for the joints whose controller
has not written a command yet, so those joints are left out of the plan and the
others are carried out; a message with nothing but NaN is an empty plan, not an
error. A target that must be reached (a MoveTo goal, a preset) is different: NaN
there is an error (:func:`validate_targets`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from gimbal_driver_common.errors import InvalidRequest


class CommandError(InvalidRequest):
    """A command was rejected; the message says which joint and value and why, ``reason``
    the same without the values (what rejected commands are counted and logged by)."""


@dataclass(frozen=True)
class JointLimits:
    """Limits of one joint in SI units (rad, rad/s; m and m/s for linear axes)."""

    position_min: float = -math.inf
    position_max: float = math.inf
    velocity_max: float = math.inf

    def __post_init__(self) -> None:
        if self.position_min > self.position_max:
            raise ValueError(
                f'position_min {self.position_min} > position_max {self.position_max}'
            )
        if not self.velocity_max > 0:
            raise ValueError(f'velocity_max must be > 0, got {self.velocity_max}')


@dataclass
class CommandPlan:
    """What a validated command asks for.

    ``moves`` maps joint -> (target position, max velocity or None for the
    default); ``jogs`` maps joint -> signed velocity.
    """

    moves: dict[str, tuple[float, float | None]] = field(default_factory=dict)
    jogs: dict[str, float] = field(default_factory=dict)

    @property
    def empty(self) -> bool:
        return not self.moves and not self.jogs


def limits_from_parameters(
    joint_names: Sequence[str],
    position_min: Sequence[float],
    position_max: Sequence[float],
    velocity_max: Sequence[float],
) -> dict[str, JointLimits]:
    """Build per-joint limits from the parallel-array parameters of docs/interface.md."""
    for label, values in (
        ('position_min', position_min),
        ('position_max', position_max),
        ('velocity_max', velocity_max),
    ):
        if len(values) != len(joint_names):
            raise ValueError(
                f'{label} has {len(values)} values but joint_names has {len(joint_names)}'
            )
    limits = {}
    for name, low, high, vmax in zip(
        joint_names, position_min, position_max, velocity_max, strict=True
    ):
        try:
            limits[name] = JointLimits(float(low), float(high), float(vmax))
        except ValueError as exc:
            raise ValueError(f'joint {name!r}: {exc}') from exc
    return limits



def _check_position(name: str, value: float, limits: JointLimits) -> None:
    if not math.isfinite(value):
        raise CommandError(f'joint {name!r}: position {value} is not a finite number',
                           reason=f'{name}: position not finite')
    if not limits.position_min <= value <= limits.position_max:
        raise CommandError(
            f'joint {name!r}: position {value:.4f} outside '
            f'[{limits.position_min:.4f}, {limits.position_max:.4f}]',
            reason=f'{name}: position outside the limits')


def _check_velocity(name: str, value: float, limits: JointLimits, what: str) -> None:
    if not math.isfinite(value):
        raise CommandError(f'joint {name!r}: {what} {value} is not a finite number',
                           reason=f'{name}: {what} not finite')
    if abs(value) > limits.velocity_max:
        raise CommandError(
            f'joint {name!r}: {what} {value:.4f} exceeds velocity_max '
            f'{limits.velocity_max:.4f}', reason=f'{name}: {what} above velocity_max')


def _check_names(names: Sequence[str], limits: Mapping[str, JointLimits],
                 arrays: Mapping[str, Sequence[float]]) -> None:
    """Names given, unique and known; each array empty or one value per name."""
    if not names:
        raise CommandError('command names no joints', reason='no joints named')
    if len(set(names)) != len(names):
        raise CommandError(f'command names a joint twice: {list(names)}',
                           reason='a joint named twice')
    for label, values in arrays.items():
        if values and len(values) != len(names):
            raise CommandError(
                f'{len(names)} joint names but {len(values)} {label} values '
                '(give one per joint, or none)', reason=f'{label} values do not match the names')
    unknown = [n for n in names if n not in limits]
    if unknown:
        raise CommandError(f'unknown joint(s) {unknown}; this device has {sorted(limits)}',
                           reason='unknown joint')


def validate_joint_command(
    names: Sequence[str],
    positions: Sequence[float],
    velocities: Sequence[float],
    limits: Mapping[str, JointLimits],
) -> CommandPlan:
    """Check a JointState-style command and return the plan, or raise CommandError.

    Rules (docs/interface.md): a position is an absolute move (a velocity alongside is its
    maximum speed; 0 or NaN: the default speed); a velocity without a position (none, or
    NaN) is a jog. ``positions`` and ``velocities`` are either empty or as long as
    ``names``. A joint whose position and velocity are both NaN (or not given) has no
    command and is left out of the plan; a message with nothing but NaN gives an empty plan.
    ±inf, unknown or repeated joints, mismatched lengths and values beyond the limits
    reject the whole command.
    """
    _check_names(names, limits, {'position': positions, 'velocity': velocities})
    plan = CommandPlan()
    for i, name in enumerate(names):
        joint_limits = limits[name]
        position = positions[i] if positions else math.nan
        velocity = velocities[i] if velocities else math.nan
        if not math.isnan(position):
            _check_position(name, position, joint_limits)
            max_speed = None
            if not math.isnan(velocity) and velocity != 0.0:
                _check_velocity(name, abs(velocity), joint_limits, 'speed')
                max_speed = abs(velocity)
            plan.moves[name] = (position, max_speed)
        elif not math.isnan(velocity):
            _check_velocity(name, velocity, joint_limits, 'velocity')
            plan.jogs[name] = velocity
    return plan


def validate_targets(
    names: Sequence[str],
    positions: Sequence[float],
    limits: Mapping[str, JointLimits],
    speeds: Sequence[float] = (),
) -> dict[str, tuple[float, float | None]]:
    """Targets that must all be reached (a MoveTo goal, a preset): joint -> (target, max
    speed or None for the default), or CommandError.

    Unlike a joint_command, a NaN position is an error here: a goal that names a joint
    promises a result for it (reached, and where it ended) and a preset stores a pose, so
    neither may leave a joint out silently. ``speeds``: empty, or one per joint (0: default).
    """
    if len(positions) != len(names):
        raise CommandError(f'{len(names)} joint names but {len(positions)} positions',
                           reason='position values do not match the names')
    _check_names(names, limits, {'velocity': speeds})
    for name, position in zip(names, positions, strict=True):
        if math.isnan(position):
            raise CommandError(
                f'joint {name!r}: position NaN is not a target (a goal or a preset needs a '
                'number for every joint it names)', reason=f'{name}: position not a number')
    return validate_joint_command(names, positions, speeds, limits).moves


def check_positions(
    positions: Mapping[str, float], limits: Mapping[str, JointLimits], what: str = '',
) -> None:
    """Raise CommandError when a pose (joint -> position) names an unknown joint or leaves
    the limits: the one pose check of presets, device programs and targets. ``what``
    names the pose in the message ("preset 3", "the target")."""
    try:
        validate_targets(list(positions), list(positions.values()), limits)
    except CommandError as exc:
        if not what:
            raise
        raise CommandError(f'{what} is outside the joint limits, not moving: {exc}',
                           reason=exc.reason) from None


def resolve_targets(
    names: Sequence[str],
    values: Sequence[float],
    current: Mapping[str, float],
    limits: Mapping[str, JointLimits],
    relative: bool = False,
) -> dict[str, float]:
    """Absolute targets for a MoveTo goal (``relative`` offsets added to ``current``)."""
    if relative:
        missing = [n for n in names if n in limits and n not in current]
        if missing:
            raise CommandError(f'no position of {missing} received yet: a relative move '
                               'needs one', reason='no current position')
        values = [current.get(n, math.nan) + v for n, v in zip(names, values, strict=False)]
    targets = validate_targets(names, list(values), limits)
    return {name: target for name, (target, _) in targets.items()}
