"""Hypothesis strategies for the requests a driver's own services must refuse.

A driver's ``DriverSpec.refused_requests`` names a function in its ``<pkg>/testing``
that returns a strategy of ``(service type, service name under the node, request)``;
``tests/test_ros_properties.py`` sends each and checks the refusal and that nothing
reached the device. These are the pieces they share.
"""

from __future__ import annotations

from hypothesis import strategies as st

from gimbal_msgs.srv import DeviceCommand

#: names of out-of-scope (weapon) functions: never encoded, so unknown to every command table
OUT_OF_SCOPE_NAMES = ('WCU_Fire', 'WCU_Trigger', 'WCU_SetSafety', 'WCU_GetShotCounter',
                      'CapSnap', 'fire', 'arm')
IDENTIFIER_TEXT = st.text(alphabet='abcdefghijklmnopqrstuvwxyz_0123456789', max_size=14)


def device_command(service: str, names: st.SearchStrategy[str]) -> st.SearchStrategy:
    """DeviceCommand requests with any axis and any argument texts."""
    return st.builds(lambda name, axis, arguments: (DeviceCommand, service, DeviceCommand.Request(
        command=name, axis=axis, arguments=arguments)),
        names, st.integers(0, 255), st.lists(st.text(max_size=12), max_size=3))


def unknown(known: set[str]) -> st.SearchStrategy[str]:
    """Names no command table has: out-of-scope names and any text outside ``known``."""
    return st.one_of(st.sampled_from(OUT_OF_SCOPE_NAMES), st.text(max_size=16)).filter(
        lambda name: name.strip() not in known)
