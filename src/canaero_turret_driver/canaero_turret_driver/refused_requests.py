"""The requests this driver's own services must refuse (``DriverSpec.refused_requests``;
``tests/test_ros_properties.py``), as plain data: the strategy is built by
``gimbal_driver_testing.refused_requests``."""

from __future__ import annotations

from gimbal_driver_common.registry import RefusedRequests

from .device import MODE_NAMES


def refused_requests() -> RefusedRequests:
    """~/device_command: unknown names, and the node-id change, flash programming and data
    download (each behind its opt-in); ~/set_actuator_mode with an unknown mode."""
    return RefusedRequests(
        command_service='device_command',
        refused_commands=('set_node_id', 'store_configuration', 'download'),
        known_commands=frozenset({'identify', 'set_interval', 'upload', 'download',
                                  'set_node_id', 'store_configuration'}),
        mode_service='set_actuator_mode', known_modes=frozenset(MODE_NAMES))
