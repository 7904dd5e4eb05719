"""Hypothesis strategies for the requests a driver's own services must refuse.

A driver's ``DriverSpec.refused_requests`` names a function of its runtime package that
returns a :class:`~gimbal_driver_common.registry.RefusedRequests` (plain data, so the
driver needs no test library); :func:`strategy` turns it into a strategy of ``(service
type, service name under the node, request)``. ``tests/test_ros_properties.py`` sends
each and checks the refusal and that nothing reached the device.
"""

from __future__ import annotations

from hypothesis import strategies as st
from std_srvs.srv import Trigger

from gimbal_driver_common.registry import RefusedRequests
from gimbal_msgs.srv import DeviceCommand, SetMode

#: names of out-of-scope (weapon) functions: never encoded, so unknown to every command table
OUT_OF_SCOPE_NAMES = ('WCU_Fire', 'WCU_Trigger', 'WCU_SetSafety', 'WCU_GetShotCounter',
                      'CapSnap', 'fire', 'arm')
IDENTIFIER_TEXT = st.text(alphabet='abcdefghijklmnopqrstuvwxyz_0123456789', max_size=14)


def device_command(service: str, names: st.SearchStrategy[str]) -> st.SearchStrategy:
    """DeviceCommand requests with any axis and any argument texts."""
    return st.builds(lambda name, axis, arguments: (DeviceCommand, service, DeviceCommand.Request(
        command=name, axis=axis, arguments=arguments)),
        names, st.integers(0, 255), st.lists(st.text(max_size=12), max_size=3))


def unknown(known: set[str] | frozenset[str]) -> st.SearchStrategy[str]:
    """Names no command table has: out-of-scope names and any text outside ``known``."""
    return st.one_of(st.sampled_from(OUT_OF_SCOPE_NAMES), st.text(max_size=16)).filter(
        lambda name: name.strip() not in known)


def unknown_mode(known: frozenset[str]) -> st.SearchStrategy[str]:
    """Mode names outside ``known``, compared stripped and lower-case (as a node that
    normalises them would; an exact-match node refuses these too)."""
    lowered = {mode.lower() for mode in known}
    return st.one_of(IDENTIFIER_TEXT, st.text(max_size=16)).filter(
        lambda mode: mode.strip().lower() not in lowered)


def strategy(refused: RefusedRequests) -> st.SearchStrategy:
    """Every request ``refused`` describes, drawn from one strategy."""
    parts: list[st.SearchStrategy] = []
    if refused.command_service:
        names: list[st.SearchStrategy[str]] = [unknown(refused.known_commands)]
        if refused.refused_commands:
            names.insert(0, st.sampled_from(refused.refused_commands))
        parts.append(device_command(refused.command_service, st.one_of(names)))
    if refused.refused_triggers:
        parts.append(st.sampled_from(refused.refused_triggers).map(
            lambda name: (Trigger, name, Trigger.Request())))
    if refused.mode_service:
        service = refused.mode_service
        parts.append(unknown_mode(refused.known_modes).map(
            lambda mode: (SetMode, service, SetMode.Request(mode=mode))))
    if not parts:
        raise ValueError(f'{refused} describes no request')
    return st.one_of(parts)
