"""The conformance suite against canaero_turret_driver_node and canaero_turret_sim (slcan
over a pseudo-terminal), as processes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from canaero_turret_driver.sim import ControlClient
from gimbal_driver_common.ros.conformance_testing import DriverConformance, SimulatorHandle
from gimbal_driver_common.testing import ManagedProcess, wait_for

PKG = "canaero_turret_driver"


class TurretSim(SimulatorHandle):
    """canaero_turret_sim as a process; its control port reports the axes and counts every
    CANaerospace command the turret received (the receive side), and drops the link."""

    def __init__(self, workdir: Path, domain: int) -> None:
        self.tty, ready = workdir / "tty", workdir / "ready.json"
        self.process = ManagedProcess.ros(PKG, "canaero_turret_sim", domain,
                                          ["--link", str(self.tty), "--ready-file", str(ready)])
        self.control: ControlClient | None = None
        try:
            wait_for(ready.exists, 30, "the simulator to start")
            self.control = ControlClient(json.loads(ready.read_text())["control_port"])
        except BaseException:
            self.process.stop()
            raise

    def link_parameters(self) -> list[str]:
        return ["can_interface:=slcan", f"can_channel:={self.tty}",
                "can_options:=['sleep_after_open=0']", "service_timeout:=0.3",
                "node_timeout:=0.6", "stale_timeout:=0.6", "actuator_mode:=auto_brake"]

    def motion_received(self) -> object:
        return self.control.state()["commands_received"]

    def moving(self, joint: str) -> bool:
        return self.control.state()["axes"][joint]["velocity"] != 0.0

    def drop_link(self, seconds: float) -> None:
        assert self.control.command(f"drop {seconds}") == "ok"

    def close(self) -> None:
        if self.control is not None:
            self.control.close()
        self.process.stop()


class TestCanaeroTurretConformance(DriverConformance):
    __test__ = True
    package = PKG
    node_executable = "canaero_turret_driver_node"
    node_name = "canaero_turret_driver"
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

    def start_simulator(self, workdir: Path, domain: int) -> SimulatorHandle:
        return TurretSim(workdir, domain)
