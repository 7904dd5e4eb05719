"""What the controller is configured with, and the logger it writes to (no ROS).

The controller attaches both to its device (:meth:`Device.attach`), so adapters read the
live limits and log without reaching up into the controller.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

from gimbal_driver_common.joint_command import JointLimits


class Logger(Protocol):
    """The part of a logger the controller uses (rclpy's and :mod:`logging`'s both fit)."""

    def info(self, msg: str) -> object: ...
    def warning(self, msg: str) -> object: ...
    def error(self, msg: str) -> object: ...


@dataclass
class ControllerConfig:
    """The common parameters of docs/interface.md, as the controller uses them (all runtime)."""

    joint_names: list[str]
    limits: dict[str, JointLimits]
    publish_rate: float = 50.0
    command_timeout: float = 0.5
    reconnect_period: float = 1.0
    goal_tolerance: float = 0.01
    move_timeout: float = 60.0
    #: s before an accepted command that shows no motion is reported (<= 0: never)
    motion_start_timeout: float = 1.0
    #: rad/s^2 an axis is trusted to brake at after a stop: its speed over this, plus
    #: ``stop_margin`` s, is how long it may take to rest before the stop is sent again
    stop_deceleration: float = 0.5
    stop_margin: float = 0.5
    #: the (pan, tilt) joints a scan sweeps; empty: pan/tilt if named so, else the first two
    scan_joints: Sequence[str] = field(default_factory=tuple)


def scan_joints(config: ControllerConfig) -> list[str]:
    """The (pan, tilt) a scan sweeps: configured, else `pan`/`tilt` by name, else the first two."""
    names = config.joint_names
    if config.scan_joints:
        return list(config.scan_joints)
    if 'pan' in names and 'tilt' in names:
        return ['pan', 'tilt']
    return list(names[:2])
