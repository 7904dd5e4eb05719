"""The conformance suite against capture_driver_node (a process) and the Capture simulator
over TCP: the registry's handle (``CaptureSimHandle``) in the test process, so the suite
sees every command the pedestal received."""

from __future__ import annotations

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from sensor_msgs.msg import Imu

from gimbal_driver_common.testing.conformance import DriverConformance
from gimbal_driver_common.testing.silent_request_conformance import SilentRequest
from gimbal_msgs.srv import DeviceCommand


class TestCaptureConformance(DriverConformance):
    __test__ = True
    driver = 'capture'
    reports_current = True  # motor current (A) in ~/status; effort via torque_constants
    joints = ('pan', 'tilt')
    small_move = {'pan': 0.4, 'tilt': -0.2}
    far_move = ('pan', -2.5, 0.1)
    jog = ('pan', 0.3)
    tolerance = 2e-3
    preset_index = 2
    scan = dict(pattern='snake', pan_min=-0.2, pan_max=0.2, tilt_min=0.0, tilt_max=0.2,
                speed=0.5, tilt_step=0.1)

    # the kinds of request a controller may leave unanswered (the simulator's mute/delay)
    silent_requests = (
        # the IMU is read while ~/imu has a subscriber, as in the measurement of the issue
        SilentRequest('sensor getter', 'IMU_GetRoll', periodic=True,
                      timeout_parameter='request_timeout', topic=('imu', Imu)),
        SilentRequest('status register', 'ERR_OperationRegister', periodic=True,
                      timeout_parameter='request_timeout'),
        SilentRequest('identity read', 'COM_GetPn', at_connect=True),
        SilentRequest('service request', 'COM_GetFw', timeout_parameter='request_timeout',
                      service=(DeviceCommand, 'command',
                               lambda: DeviceCommand.Request(command='COM_GetFw'))),
    )
    required_request = ('COM_Connect', 'COM_Connect')
    handshake_request = 'COM_Connect'
