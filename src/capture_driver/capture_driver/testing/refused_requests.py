"""The requests this driver's own services must refuse (``DriverSpec.refused_requests``;
``tests/test_ros_properties.py``)."""

from __future__ import annotations

from hypothesis import strategies as st

from gimbal_driver_common.testing.refused_requests import device_command, unknown

from ..command_text import ALLOWED_MOTION
from ..protocol import COMMANDS, Safety


def refused_requests() -> st.SearchStrategy:
    """~/command: unknown names, and every table command gated behind an opt-in parameter
    (non-volatile writes, reboots, network settings) or one that starts motion without the
    driver's limit checks."""
    gated = sorted(name for name, command in COMMANDS.items()
                   if command.safety in (Safety.NV_WRITE, Safety.REBOOT, Safety.NETWORK)
                   or (command.safety is Safety.MOTION and name not in ALLOWED_MOTION))
    return device_command('command', st.one_of(st.sampled_from(gated), unknown(set(COMMANDS))))
