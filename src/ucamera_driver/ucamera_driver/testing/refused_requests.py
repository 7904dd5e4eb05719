"""The requests this driver's own services must refuse (``DriverSpec.refused_requests``;
``tests/test_ros_properties.py``)."""

from __future__ import annotations

from hypothesis import strategies as st
from std_srvs.srv import Trigger

from gimbal_msgs.srv import SetMode

from ..protocol.packets import MODE_NAMES


def refused_requests() -> st.SearchStrategy:
    """~/save_configuration and ~/save_ffc (non-volatile writes, behind allow_nv_write);
    ~/set_mode with an unknown mode."""
    saves = st.sampled_from(('save_configuration', 'save_ffc')).map(
        lambda name: (Trigger, name, Trigger.Request()))
    mode = st.text(max_size=16).filter(lambda m: m.strip().lower() not in MODE_NAMES)
    return st.one_of(saves, mode.map(lambda m: (SetMode, 'set_mode', SetMode.Request(mode=m))))
