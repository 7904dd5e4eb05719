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

from gimbal_driver_common.ros.look_at_testing import LookAtRig, LookAtSuite, look_at_rig_against
from gimbal_driver_common.testing import DomainLease, ManagedProcess, ros_arguments, wait_for

pytestmark = pytest.mark.ros

PKG = "ucamera_driver"
SIM_ARGS = ["--init-time", "0.1", "--max-rate", "180", "--acceleration", "1800"]


def device_angles_deg(sim: ManagedProcess, fifo: str) -> tuple[float, float]:
    """(pan, tilt) in device degrees: the simulator prints a status line on request."""
    before = sim.output().count("mode=")
    with open(fifo, "w", encoding="utf-8") as pipe:
        pipe.write("status\n")
    wait_for(lambda: sim.output().count("mode=") > before, 10.0, "sim status")
    line = [x for x in sim.output().splitlines() if "mode=" in x][-1]
    return (float(re.search(r"pan=(-?[\d.]+)deg", line).group(1)),
            float(re.search(r"tilt=(-?[\d.]+)deg", line).group(1)))


@pytest.fixture(scope="module")
def look_at_rig(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ucamera_look_at")
    link, fifo = str(tmp / "tty"), str(tmp / "control")
    with DomainLease() as domain:
        sim = ManagedProcess.ros(PKG, "ucamera_sim", domain,
                                 ["--link", link, "--control-fifo", fifo, *SIM_ARGS])

        def start_node() -> ManagedProcess:
            sim.wait_for_output(link)
            return ManagedProcess.ros(PKG, "ucamera_driver_node", domain, ros_arguments([
                f"serial_port:={link}", "reconnect_period:=0.3",
                f"presets_file:={tmp / 'presets.yaml'}", f"position_min:=[{-math.pi}, -0.8]"]))

        with look_at_rig_against(PKG, domain, sim, start_node,
                                 lambda: device_angles_deg(sim, fifo)) as rig:
            yield rig


class TestLookAt(LookAtSuite):
    def test_look_at_left_is_a_negative_device_pan(self, look_at_rig: LookAtRig) -> None:
        look_at_rig.check.look_and_reach(math.pi / 2, LookAtSuite.UP)
        pan, tilt = look_at_rig.device_state()
        assert pan == pytest.approx(-90.0, abs=1.0)
        assert tilt == pytest.approx(math.degrees(LookAtSuite.UP), abs=1.0)
