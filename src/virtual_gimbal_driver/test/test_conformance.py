"""The conformance suite against the reference virtual gimbal: the node as a process, the
simulator the registry's handle (``VirtualGimbalSim``) in the test process."""

from __future__ import annotations

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from std_srvs.srv import Trigger

from gimbal_driver_testing.conformance import DriverConformance
from gimbal_driver_testing.silent_request_conformance import SilentRequest


class TestVirtualGimbalConformance(DriverConformance):
    __test__ = True
    driver = 'virtual_gimbal'
    joints = ('pan', 'tilt')
    small_move = {'pan': 0.4, 'tilt': -0.2}
    far_move = ('pan', -2.5, 0.3)
    jog = ('tilt', 0.2)
    tolerance = 0.011
    preset_index = 4
    scan = dict(pattern='sector', pan_min=-0.2, pan_max=0.2, speed=1.2)
    silent_requests = (
        SilentRequest('identity read', 'ID', at_connect=True),
        SilentRequest('service request', 'RESET', timeout_parameter='request_timeout',
                      service=(Trigger, 'reset_faults', Trigger.Request)),
    )
    required_request = ('GET', 'no reply to GET')
    handshake_request = 'ID'
