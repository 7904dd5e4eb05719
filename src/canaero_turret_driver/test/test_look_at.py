"""~/look_at of the turret node (process) against canaero_turret_sim (slcan over a pty).

The turret's own pitch limits (-30..+60 deg) are the node's defaults, so a point 69 deg
below the horizon is beyond them as shipped.
"""

from __future__ import annotations

import json
import math

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from canaero_turret_driver.sim import ControlClient
from gimbal_driver_testing import DomainLease, ManagedProcess, ros_arguments, wait_for
from gimbal_driver_testing.look_at import LookAtRig, LookAtSuite, look_at_rig_against

pytestmark = pytest.mark.ros

PKG = "canaero_turret_driver"


@pytest.fixture(scope="module")
def look_at_rig(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("canaero_look_at")
    tty, ready = tmp / "tty", tmp / "ready.json"
    controls: list[ControlClient] = []
    with DomainLease() as domain:
        sim = ManagedProcess.ros(PKG, "canaero_turret_sim", domain,
                                 ["--link", str(tty), "--ready-file", str(ready)])

        def start_node() -> ManagedProcess:
            wait_for(ready.exists, 20, "the simulator to start")
            controls.append(ControlClient(json.loads(ready.read_text())["control_port"]))
            params = [
                "can_interface:=slcan", f"can_channel:={tty}",
                "can_options:=['sleep_after_open=0']", "reconnect_period:=0.3",
                f"presets_file:={tmp / 'presets.yaml'}", "publish_rate:=20.0",
                "transmission_intervals:=['yaw_position=20','pitch_position=20']",
            ]
            return ManagedProcess.ros(PKG, "canaero_turret_driver_node", domain,
                                      ros_arguments(params))

        try:
            with look_at_rig_against(PKG, domain, sim, start_node,
                                     lambda: controls[0].state()["commands_received"]) as rig:
                rig.simulator = controls[0]
                yield rig
        finally:
            for control in controls:
                control.close()


class TestLookAt(LookAtSuite):
    def test_look_at_left_and_up_reach_the_device(self, look_at_rig: LookAtRig) -> None:
        look_at_rig.check.look_and_reach(math.pi / 2, LookAtSuite.UP)
        axes = look_at_rig.simulator.state()["axes"]  # degrees, REP-103 signs
        assert axes["yaw"]["position"] == pytest.approx(90.0, abs=1.0)
        assert axes["pitch"]["position"] == pytest.approx(math.degrees(LookAtSuite.UP), abs=1.0)
