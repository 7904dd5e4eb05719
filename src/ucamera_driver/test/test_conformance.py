"""The conformance suite against ucamera_driver_node (a process) and the U-Camera simulator
on a real pseudo-terminal: the registry's handle (``UCameraSimHandle``) in the test process,
so the suite reads what the gimbal received."""

from __future__ import annotations

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from gimbal_driver_testing.conformance import ConformanceRig, DriverConformance
from gimbal_driver_testing.silent_request_conformance import SilentRequest
from gimbal_msgs.msg import GimbalStatus


class TestUCameraConformance(DriverConformance):
    __test__ = True
    driver = "ucamera"
    joints = ("pan", "tilt")
    small_move = {"pan": 0.4, "tilt": -0.2}
    far_move = ("pan", -2.5, 0.2)
    jog = ("tilt", 0.4)
    tolerance = 0.02
    preset_index = 3
    scan = dict(pattern="sector", pan_min=-0.3, pan_max=0.3, speed=1.0)

    # the kinds of request a gimbal may leave unanswered (the simulator's mute/delay): UCSP
    # has no request the node makes on its own after connecting
    silent_requests = (
        SilentRequest("read-back", "TelemetryRateRequest", at_connect=True),
        SilentRequest("identity read", "AntennaPositionRequest", at_connect=True),
    )
    required_request = ("VersionRequest", "Request Gimbal Version")
    handshake_request = "VersionRequest"

    def node_parameters(self) -> list[str]:
        return [*super().node_parameters(), "velocity_max:=[3.0, 3.0]"]

    def check_jog_running(self, rig: ConformanceRig) -> None:
        # a jog runs in the gimbal's rates mode
        rig.ros.wait_for_message(f"/{self.node_name}/status", GimbalStatus,
                                 lambda s: s.mode == "rates", timeout=15)
