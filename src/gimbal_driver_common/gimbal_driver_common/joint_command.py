"""Validate joint commands against per-joint limits before anything is sent.

``joint_command`` (sensor_msgs/JointState) and the MoveTo action carry names
with positions and/or velocities. This module turns them into a
:class:`CommandPlan` of absolute moves and jogs, or rejects the whole command
with a :class:`CommandError` naming the joint, the value and the limit, so a
bad command never reaches the device half-applied.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from gimbal_driver_common.errors import InvalidRequest


class CommandError(InvalidRequest):
    """A command was rejected; the message says which joint and value and why."""


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

    def clamp_position(self, position: float) -> float:
        return min(max(position, self.position_min), self.position_max)


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
    """Build per-joint limits from the parallel-array parameters of interfaces.md."""
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
        raise CommandError(f'joint {name!r}: position {value} is not a finite number')
    if not limits.position_min <= value <= limits.position_max:
        raise CommandError(
            f'joint {name!r}: position {value:.4f} outside '
            f'[{limits.position_min:.4f}, {limits.position_max:.4f}]'
        )


def _check_velocity(name: str, value: float, limits: JointLimits, what: str) -> None:
    if not math.isfinite(value):
        raise CommandError(f'joint {name!r}: {what} {value} is not a finite number')
    if abs(value) > limits.velocity_max:
        raise CommandError(
            f'joint {name!r}: {what} {value:.4f} exceeds velocity_max {limits.velocity_max:.4f}'
        )


def validate_joint_command(
    names: Sequence[str],
    positions: Sequence[float],
    velocities: Sequence[float],
    limits: Mapping[str, JointLimits],
) -> CommandPlan:
    """Check a JointState-style command and return the plan, or raise CommandError.

    Rules (interfaces.md): a position is an absolute move (a velocity alongside
    is its maximum speed); a velocity without a position is a jog. ``positions``
    and ``velocities`` are either empty or as long as ``names``; NaN in a
    position slot means "no position for this joint" (as in JointState for
    mixed commands).
    """
    if not names:
        raise CommandError('command names no joints')
    if len(set(names)) != len(names):
        raise CommandError(f'command names a joint twice: {list(names)}')
    for label, values in (('position', positions), ('velocity', velocities)):
        if values and len(values) != len(names):
            raise CommandError(
                f'{len(names)} joint names but {len(values)} {label} values '
                '(give one per joint, or none)'
            )
    unknown = [n for n in names if n not in limits]
    if unknown:
        raise CommandError(f'unknown joint(s) {unknown}; this device has {sorted(limits)}')
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
        else:
            raise CommandError(f'joint {name!r}: neither a position nor a velocity was given')
    return plan


def check_positions(
    positions: Mapping[str, float], limits: Mapping[str, JointLimits], what: str = '',
) -> None:
    """Raise CommandError when a pose (joint -> position) names an unknown joint or leaves
    the limits: the one pose check of presets, device programs and targets. ``what``
    names the pose in the message ("preset 3", "the target")."""
    try:
        validate_joint_command(list(positions), list(positions.values()), [], limits)
    except CommandError as exc:
        if not what:
            raise
        raise CommandError(f'{what} is outside the joint limits, not moving: {exc}') from None


def resolve_targets(
    names: Sequence[str],
    values: Sequence[float],
    current: Mapping[str, float],
    limits: Mapping[str, JointLimits],
    relative: bool = False,
) -> dict[str, float]:
    """Absolute targets for a MoveTo goal (``relative`` offsets added to ``current``)."""
    if len(values) != len(names):
        raise CommandError(f'{len(names)} joint names but {len(values)} positions')
    plan = validate_joint_command(
        names,
        [
            (current.get(n, math.nan) + v) if relative else v
            for n, v in zip(names, values, strict=True)
        ],
        [],
        limits,
    )
    return {name: target for name, (target, _) in plan.moves.items()}
