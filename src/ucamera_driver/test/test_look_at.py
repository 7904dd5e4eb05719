"""~/look_at of ucamera_driver_node (process) against ucamera_sim (UCSP over a pty).

The U-Camera counts pan clockwise; the driver negates it, so look_at works in REP-103
joint space and the simulator reports the negated pan angle.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip("rclpy", reason="node tests need the ROS environment")
pytest.importorskip("gimbal_msgs", reason="node tests need the built workspace (make build)")

from gimbal_driver_common.sim_control import control_state
from gimbal_driver_testing import DomainLease, ManagedProcess, ros_arguments, wait_for_ready
from gimbal_driver_testing.look_at import LookAtRig, LookAtSuite, look_at_rig_against

pytestmark = pytest.mark.ros

PKG = "ucamera_driver"
SIM_ARGS = ["--init-time", "0.1", "--max-rate", "180", "--acceleration", "1800"]


def device_angles_deg(control_port: int) -> tuple[float, float]:
    """(pan, tilt) in device degrees, from the simulator's ``state`` answer."""
    axes = control_state(control_port)["axes"]
    return math.degrees(axes["pan"]["position"]), math.degrees(axes["tilt"]["position"])


@pytest.fixture(scope="module")
def look_at_rig(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ucamera_look_at")
    link = str(tmp / "tty")
    with DomainLease() as domain:
        sim = ManagedProcess.ros(PKG, "ucamera_sim", domain, ["--link", link, *SIM_ARGS])
        control_port = wait_for_ready(sim, "ucamera_sim")["control_port"]

        def start_node() -> ManagedProcess:
            return ManagedProcess.ros(PKG, "ucamera_driver_node", domain, ros_arguments([
                f"serial_port:={link}", "reconnect_period:=0.3",
                f"presets_file:={tmp / 'presets.yaml'}", f"position_min:=[{-math.pi}, -0.8]"]))

        with look_at_rig_against(PKG, domain, sim, start_node,
                                 lambda: device_angles_deg(control_port)) as rig:
            yield rig


class TestLookAt(LookAtSuite):
    def test_look_at_left_is_a_negative_device_pan(self, look_at_rig: LookAtRig) -> None:
        look_at_rig.check.look_and_reach(math.pi / 2, LookAtSuite.UP)
        pan, tilt = look_at_rig.device_state()
        assert pan == pytest.approx(-90.0, abs=1.0)
        assert tilt == pytest.approx(math.degrees(LookAtSuite.UP), abs=1.0)
