"""The requests this driver's own services must refuse (``DriverSpec.refused_requests``;
``tests/test_ros_properties.py``)."""

from __future__ import annotations

from hypothesis import strategies as st

from gimbal_driver_common.testing.refused_requests import (
    IDENTIFIER_TEXT,
    device_command,
    unknown,
)
from gimbal_msgs.srv import SetMode

from ..node import MODE_NAMES


def refused_requests() -> st.SearchStrategy:
    """~/device_command: unknown names, and the node-id change, flash programming and data
    download (each behind its opt-in); ~/set_actuator_mode with an unknown mode."""

    known = {'identify', 'set_interval', 'upload', 'download', 'set_node_id',
             'store_configuration'}
    gated = st.sampled_from(('set_node_id', 'store_configuration', 'download'))
    mode = IDENTIFIER_TEXT.filter(lambda m: m not in MODE_NAMES)
    return st.one_of(device_command('device_command', st.one_of(gated, unknown(known))),
                     mode.map(lambda m: (SetMode, 'set_actuator_mode', SetMode.Request(mode=m))))
