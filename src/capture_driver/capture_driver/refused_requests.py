"""The requests this driver's own services must refuse (``DriverSpec.refused_requests``;
``tests/test_ros_properties.py``), as plain data: the strategy is built by
``gimbal_driver_testing.refused_requests``."""

from __future__ import annotations

from gimbal_driver_common.registry import RefusedRequests

from .command_text import ALLOWED_MOTION
from .protocol import COMMANDS, Safety


def refused_requests() -> RefusedRequests:
    """~/command: unknown names, and every table command gated behind an opt-in parameter
    (non-volatile writes, reboots, network settings) or one that starts motion without the
    driver's limit checks."""
    gated = sorted(name for name, command in COMMANDS.items()
                   if command.safety in (Safety.NV_WRITE, Safety.REBOOT, Safety.NETWORK)
                   or (command.safety is Safety.MOTION and name not in ALLOWED_MOTION))
    return RefusedRequests(command_service='command', refused_commands=tuple(gated),
                           known_commands=frozenset(COMMANDS))
