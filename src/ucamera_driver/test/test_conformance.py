"""The conformance suite against ucamera_driver_node (a process) and the U-Camera simulator
on a real pseudo-terminal (in the test process, so the suite reads what the gimbal
received)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from gimbal_driver_common.ros.conformance_testing import (
    ConformanceRig,
    DriverConformance,
    SimulatorHandle,
)
from gimbal_msgs.msg import GimbalStatus
from ucamera_driver.sim import SimConfig, UCameraSim


class InProcessUCamera(SimulatorHandle):
    """UCameraSim serving a pty link from the test process.

    The driver re-sends mode and angles/rates at ``refresh_rate``, so "nothing sent" is
    judged on what the gimbal was told to do (mode, commanded angles and rates as
    received), not on a packet count.
    """

    def __init__(self, workdir: Path) -> None:
        config = SimConfig(init_time=0.1, max_rate=math.radians(180.0),
                           acceleration=math.radians(1800.0), autoalign_time=0.3,
                           ffc_time=0.3, save_pause=0.5)
        self.link = str(workdir / "tty")
        self.sim = UCameraSim(config, link_path=self.link).start()

    def link_parameters(self) -> list[str]:
        return [f"serial_port:={self.link}", "velocity_max:=[3.0, 3.0]",
                "silence_timeout:=0.5"]

    def motion_received(self) -> object:
        model = self.sim.model
        with model.lock:
            return (model.mode, model.commanded_angles, model.commanded_rates)

    def moving(self, joint: str) -> bool:
        model = self.sim.model
        with model.lock:
            return abs(getattr(model, joint).velocity) > 1e-6

    def drop_link(self, seconds: float) -> None:
        self.sim.drop_link(seconds)

    def close(self) -> None:
        self.sim.stop()


class TestUCameraConformance(DriverConformance):
    __test__ = True
    package = "ucamera_driver"
    node_executable = "ucamera_driver_node"
    node_name = "ucamera_driver"
    joints = ("pan", "tilt")
    small_move = {"pan": 0.4, "tilt": -0.2}
    far_move = ("pan", -2.5, 0.2)
    jog = ("tilt", 0.4)
    tolerance = 0.02
    preset_index = 3
    scan = dict(pattern="sector", pan_min=-0.3, pan_max=0.3, speed=1.0)

    def start_simulator(self, workdir: Path, domain: int) -> SimulatorHandle:
        return InProcessUCamera(workdir)

    def check_jog_running(self, rig: ConformanceRig) -> None:
        # a jog runs in the gimbal's rates mode
        rig.ros.wait_for_message(f"/{self.node_name}/status", GimbalStatus,
                                 lambda s: s.mode == "rates", timeout=15)
