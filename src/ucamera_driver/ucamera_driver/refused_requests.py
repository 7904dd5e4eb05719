"""The requests this driver's own services must refuse (``DriverSpec.refused_requests``;
``tests/test_ros_properties.py``), as plain data: the strategy is built by
``gimbal_driver_testing.refused_requests``."""

from __future__ import annotations

from gimbal_driver_common.registry import RefusedRequests

from .protocol.packets import MODE_NAMES


def refused_requests() -> RefusedRequests:
    """~/save_configuration and ~/save_ffc (non-volatile writes, behind allow_nv_write);
    ~/set_mode with an unknown mode."""
    return RefusedRequests(refused_triggers=('save_configuration', 'save_ffc'),
                           mode_service='set_mode', known_modes=frozenset(MODE_NAMES))
