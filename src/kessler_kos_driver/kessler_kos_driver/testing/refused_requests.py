"""The requests this driver's own services must refuse (``DriverSpec.refused_requests``;
``tests/test_ros_properties.py``)."""

from __future__ import annotations

from hypothesis import strategies as st

from gimbal_driver_common.testing.refused_requests import device_command, unknown


def refused_requests() -> st.SearchStrategy:
    """~/command: unknown names, and SetSoftwareID (behind allow_software_id_write)."""
    known = {'GetLEDStatus', 'SetLEDStatus', 'GetSoftwareID', 'SetSoftwareID'}
    return device_command('command', st.one_of(st.just('SetSoftwareID'), unknown(known)))
