"""The conformance suite against canaero_turret_driver_node (a process) and the turret
simulator behind slcan on a pseudo-terminal: the registry's handle (``CanaeroSimHandle``) in
the test process, so the suite sees every CANaerospace command the turret received."""

from __future__ import annotations

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from gimbal_driver_testing.conformance import DriverConformance
from gimbal_driver_testing.silent_request_conformance import SilentRequest
from gimbal_msgs.srv import DeviceCommand


class TestCanaeroTurretConformance(DriverConformance):
    __test__ = True
    driver = "canaero_turret"
    reports_current = True  # motor current (A) in ~/status; effort via torque_constants
    joints = ("yaw", "pitch")
    small_move = {"yaw": 0.4, "pitch": 0.2}
    far_move = ("yaw", -2.5, 0.2)
    jog = ("pitch", 0.2)
    tolerance = 0.011
    preset_index = 3
    has_home = False
    home_refusal = "no homing routine"
    scan = dict(pattern="sector", pan_min=-0.2, pan_max=0.2, speed=0.5)
    scan_joint = "yaw"
    # the kinds of request a turret may leave unanswered (the simulator's mute/delay): the
    # joint data is broadcast, so only node services are requests
    silent_requests = (
        SilentRequest("identity read", "IDS", at_connect=True),
        SilentRequest("service request", "IDS", timeout_parameter="service_timeout",
                      service=(DeviceCommand, "device_command",
                               lambda: DeviceCommand.Request(command="identify"))),
    )
