"""The conformance suite against kessler_kos_driver_node (a process) and the kOS simulator
over TCP: the registry's handle (``KesslerSimHandle``) in the test process, so the suite
sees every message the device received."""

from __future__ import annotations

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_testing.conformance import DriverConformance
from gimbal_driver_testing.silent_request_conformance import SilentRequest
from gimbal_msgs.srv import DeviceCommand


class TestKesslerKosConformance(DriverConformance):
    __test__ = True
    driver = 'kessler_kos'
    # SI on the simulator's example rig (the spec's calibrated_spans/joint_offsets,
    # registration.SIM_RIG): pan -pi..pi rad, tilt -pi/2..pi/2 rad, slider 0..1.5 m
    joints = ('pan', 'tilt', 'slider')
    small_move = {'pan': 0.3, 'tilt': 0.2}
    far_move = ('pan', 3.0, 0.05)
    jog = ('pan', 0.5)
    tolerance = 0.011
    preset_index = 4
    scan = dict(pattern='sector', pan_min=-0.5, pan_max=0.5, speed=0.5)
    # the kinds of request a device may leave unanswered (the simulator's mute/delay)
    silent_requests = (
        SilentRequest('identity read', 'GetDeviceGuid', at_connect=True),
        SilentRequest('service request', 'GetLedStatus', timeout_parameter='reply_timeout',
                      service=(DeviceCommand, 'command',
                               lambda: DeviceCommand.Request(command='GetLEDStatus'))),
    )
    required_request = ('GetDeviceInfo', 'GetDeviceInfo')
    handshake_request = 'GetDeviceInfo'
