"""The common parameters of docs/interface.md, declared once for every driver node."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from gimbal_driver_common.controller import ControllerConfig
from gimbal_driver_common.joint_command import JointLimits, limits_from_parameters
from gimbal_driver_common.ros.parameters import ParameterError, ValueOf, declare, plain_value

TORQUE_CONSTANTS = 'torque_constants'


def limits_from(joint_names: Sequence[str], value_of: ValueOf) -> dict[str, JointLimits]:
    """Per-joint limits from position_min/position_max/velocity_max (start-up and set)."""
    try:
        return limits_from_parameters(
            list(joint_names), value_of('position_min'), value_of('position_max'),
            value_of('velocity_max'))
    except ValueError as exc:
        raise ParameterError(f'joint limits: {exc}') from exc


def torque_constants_from(joint_names: Sequence[str], value: Any) -> dict[str, float]:
    """The ``torque_constants`` parameter by joint (empty: no effort in joint_states).

    Empty, or one finite positive value per joint, in N*m/A (N/A for a linear axis): the
    device's motor current times it is the joint's effort. ParameterError otherwise.
    """
    values = [float(v) for v in plain_value(value)]
    if not values:
        return {}
    if len(values) != len(joint_names):
        raise ParameterError(
            f'parameter {TORQUE_CONSTANTS!r}: {len(values)} values but joint_names has '
            f'{len(joint_names)}; give one N*m/A per joint, or [] for no effort')
    bad = [v for v in values if not (math.isfinite(v) and v > 0.0)]
    if bad:
        raise ParameterError(f'parameter {TORQUE_CONSTANTS!r}: {bad[0]} is not a finite '
                             'torque constant > 0 (N*m/A)')
    return dict(zip(joint_names, values, strict=True))


def declare_torque_constants(node: Any) -> dict[str, float]:
    """Declare ``torque_constants`` (runtime: ``ros2 param set`` applies it at once)."""
    names = list(node.joint_names)
    constants = torque_constants_from(names, declare(
        node, TORQUE_CONSTANTS, [],
        'N*m/A per joint (N/A for a linear axis): joint_states effort = motor current x '
        'this; [] = no effort (amperes are never published as effort; ~/status has the '
        'current in A)', element_type=float))

    def apply(value: Any) -> None:
        node.torque_constants = torque_constants_from(names, value)

    node.parameter_registry.make_runtime(
        TORQUE_CONSTANTS, apply, check=lambda value: torque_constants_from(names, value))
    return constants


def declare_common_parameters(node: Any) -> ControllerConfig:
    """Declare them on ``node`` (attributes of the same names) and return the controller's config.

    ``node`` is a GimbalDriverNode: its DEFAULT_* class attributes give the defaults.
    """
    node.joint_names = declare(
        node, 'joint_names', list(node.DEFAULT_JOINT_NAMES),
        'names used in joint_states and commands', read_only=True, element_type=str)
    names = node.joint_names
    if not names or len(set(names)) != len(names):
        raise ParameterError(f'parameter joint_names: need unique names, got {names}')

    def per_joint(values: Sequence[float]) -> list[float]:
        values = list(values)
        return values if len(values) == len(names) else (values + values[-1:] * len(names))[
            :len(names)]

    node.publish_rate = declare(node, 'publish_rate', float(node.DEFAULT_PUBLISH_RATE),
                                'joint_states rate in Hz', value_range=(0.1, 1000.0))
    node.diagnostics_period = declare(node, 'diagnostics_period', 1.0,
                                      'seconds between /diagnostics messages',
                                      value_range=(0.05, 60.0))
    node.command_timeout = declare(
        node, 'command_timeout', 0.5,
        'jog dead-man timeout in s: a jog stops if no joint_command arrives in time '
        '(<= 0 disables)', value_range=(-1.0, 3600.0))
    node.reconnect_period = declare(node, 'reconnect_period', 1.0,
                                    'seconds between reconnect attempts',
                                    value_range=(0.05, 600.0))
    limits = {
        'position_min': declare(node, 'position_min', per_joint(node.DEFAULT_POSITION_MIN),
                                'lowest position per joint (rad, m for linear axes)'),
        'position_max': declare(node, 'position_max', per_joint(node.DEFAULT_POSITION_MAX),
                                'highest position per joint (rad, m for linear axes)'),
        'velocity_max': declare(node, 'velocity_max', per_joint(node.DEFAULT_VELOCITY_MAX),
                                'highest speed per joint (rad/s, m/s for linear axes)'),
    }
    node.presets_file = declare(node, 'presets_file', '',
                                'YAML file where driver-side presets persist ("" = memory)')
    node.goal_tolerance = declare(node, 'goal_tolerance', 0.01,
                                  'rad: a move is done when every joint is this close',
                                  value_range=(1e-6, 1.0))
    node.move_timeout = declare(node, 'move_timeout', 60.0,
                                's: a MoveTo goal fails if not reached in time',
                                value_range=(0.1, 3600.0))
    node.motion_start_timeout = declare(
        node, 'motion_start_timeout', 1.0,
        's: an accepted move or jog whose axis shows no motion for this long is reported '
        '(diagnostics WARN, a running goal ends); <= 0 disables', value_range=(-1.0, 600.0))
    node.stop_deceleration = declare(
        node, 'stop_deceleration', float(node.DEFAULT_STOP_DECELERATION),
        'rad/s^2 (m/s^2) every axis brakes at, at least, after a stop: its speed over this '
        'plus stop_margin is how long it may take to rest before the stop is sent again',
        value_range=(1e-3, 1000.0))
    node.stop_margin = declare(
        node, 'stop_margin', 0.5,
        's an axis may take beyond its braking time to confirm a stop (at rest)',
        value_range=(0.05, 60.0))
    node.torque_constants = declare_torque_constants(node)
    node.autostart = declare(node, 'autostart', True,
                             'walk the lifecycle to active by itself (false for managed bring-up)')
    return ControllerConfig(
        joint_names=list(names), limits=limits_from(names, limits.__getitem__),
        publish_rate=node.publish_rate, command_timeout=node.command_timeout,
        reconnect_period=node.reconnect_period, goal_tolerance=node.goal_tolerance,
        move_timeout=node.move_timeout, motion_start_timeout=node.motion_start_timeout,
        stop_deceleration=node.stop_deceleration, stop_margin=node.stop_margin,
        scan_joints=tuple(node.SCAN_JOINTS or ()))
