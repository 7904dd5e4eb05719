"""~/look_at of ucamera_driver_node (process) against ucamera_sim (UCSP over a pty).

The U-Camera counts pan clockwise; the driver negates it, so look_at works in REP-103
joint space and the simulator reports the negated pan angle.
"""

from __future__ import annotations

import math
import re

import pytest

pytest.importorskip("rclpy", reason="node tests need the ROS environment")
pytest.importorskip("gimbal_msgs", reason="node tests need the built workspace (make build)")
from sensor_msgs.msg import JointState

from gimbal_driver_common.ros.look_at_testing import LookAtCheck, installed_description
from gimbal_driver_common.ros.testing import RosTestClient
from gimbal_driver_common.testing import DomainLease, ManagedProcess, wait_for

pytestmark = pytest.mark.ros

PKG = "ucamera_driver"
NODE = "ucamera_driver"
SIM_ARGS = ["--init-time", "0.1", "--max-rate", "180", "--acceleration", "1800"]
TILT_MIN = -0.8  # rad: narrower than the default so a low point is beyond the limit


class SimStatus:
    """Reads the simulator's angles through its control FIFO (it prints a status line)."""

    def __init__(self, sim: ManagedProcess, fifo: str) -> None:
        self.sim, self.fifo = sim, fifo

    def angles_deg(self) -> tuple[float, float]:
        before = self.sim.output().count("mode=")
        with open(self.fifo, "w", encoding="utf-8") as pipe:
            pipe.write("status\n")
        wait_for(lambda: self.sim.output().count("mode=") > before, 10.0, "sim status")
        line = [x for x in self.sim.output().splitlines() if "mode=" in x][-1]
        pan = float(re.search(r"pan=(-?[\d.]+)deg", line).group(1))
        tilt = float(re.search(r"tilt=(-?[\d.]+)deg", line).group(1))
        return pan, tilt


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ucamera_look_at")
    link, fifo = str(tmp / "tty"), str(tmp / "control")
    with DomainLease() as domain:
        sim = ManagedProcess.ros(PKG, "ucamera_sim", domain,
                                 ["--link", link, "--control-fifo", fifo, *SIM_ARGS])
        node = None
        try:
            sim.wait_for_output(link)
            params = {"serial_port": link, "reconnect_period": "0.3",
                      "presets_file": str(tmp / "presets.yaml"),
                      "position_min": f"[{-math.pi}, {TILT_MIN}]"}
            node = ManagedProcess.ros(PKG, "ucamera_driver_node", domain, [
                "--ros-args", *[x for k, v in params.items() for x in ("-p", f"{k}:={v}")]])
            with RosTestClient(domain) as ros:
                ros.wait_for_message("joint_states", JointState, timeout=30, fresh=False)
                yield LookAtCheck(ros, NODE, installed_description(PKG)), SimStatus(sim, fifo)
        finally:
            if node is not None:
                node.stop()
            sim.stop()


def test_look_at_straight_ahead(rig):
    check, _ = rig
    check.look_and_reach(0.0, 0.0)


def test_look_at_to_the_left_is_negative_device_pan(rig):
    check, sim = rig
    check.look_and_reach(math.pi / 2, 0.0)
    pan, _ = sim.angles_deg()
    assert pan == pytest.approx(-90.0, abs=1.0)


def test_look_at_up(rig):
    check, sim = rig
    check.look_and_reach(0.0, 0.5)
    _, tilt = sim.angles_deg()
    assert tilt == pytest.approx(math.degrees(0.5), abs=1.0)


def test_look_at_beyond_the_tilt_limit_is_refused_and_sends_nothing(rig):
    check, sim = rig
    before = sim.angles_deg()
    check.refused(check.point_for(0.0, -1.2), "position_min")
    assert sim.angles_deg() == before


def test_look_at_in_another_frame_is_refused(rig):
    check, _ = rig
    check.refused(check.point_for(0.0, 0.0), "transform the point first", frame="map")
