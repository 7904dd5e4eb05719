"""The requests this driver's own services must refuse (``DriverSpec.refused_requests``;
``tests/test_ros_properties.py``), as plain data: the strategy is built by
``gimbal_driver_testing.refused_requests``."""

from __future__ import annotations

from gimbal_driver_common.registry import RefusedRequests


def refused_requests() -> RefusedRequests:
    """~/command: unknown names, and SetSoftwareID (behind allow_software_id_write)."""
    return RefusedRequests(
        command_service='command', refused_commands=('SetSoftwareID',),
        known_commands=frozenset({'GetLEDStatus', 'SetLEDStatus', 'GetSoftwareID',
                                  'SetSoftwareID'}))
