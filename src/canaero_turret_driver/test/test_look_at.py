"""~/look_at of the turret node (process) against canaero_turret_sim (slcan over a pty).

The turret's own pitch limits (-30..+60 deg) are the node's defaults, so a point 69 deg
below the horizon is beyond them as shipped.
"""

from __future__ import annotations

import json
import math

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from sensor_msgs.msg import JointState

from canaero_turret_driver.sim import ControlClient
from gimbal_driver_common.ros.look_at_testing import LookAtCheck, installed_description
from gimbal_driver_common.ros.testing import RosTestClient
from gimbal_driver_common.testing import DomainLease, ManagedProcess, wait_for

pytestmark = pytest.mark.ros

PKG = "canaero_turret_driver"
NODE = "canaero_turret_driver"


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("canaero_look_at")
    tty, ready = tmp / "tty", tmp / "ready.json"
    with DomainLease() as domain:
        sim = ManagedProcess.ros(PKG, "canaero_turret_sim", domain,
                                 ["--link", str(tty), "--ready-file", str(ready)])
        node = control = None
        try:
            wait_for(ready.exists, 20, "the simulator to start")
            control = ControlClient(json.loads(ready.read_text())["control_port"])
            params = [
                "can_interface:=slcan", f"can_channel:={tty}",
                "can_options:=['sleep_after_open=0']", "reconnect_period:=0.3",
                f"presets_file:={tmp / 'presets.yaml'}", "publish_rate:=20.0",
                "transmission_intervals:=['yaw_position=20','pitch_position=20']",
            ]
            node = ManagedProcess.ros(PKG, "canaero_turret_driver_node", domain,
                                      ["--ros-args", *[x for p in params for x in ("-p", p)]])
            with RosTestClient(domain) as ros:
                ros.wait_for_message("joint_states", JointState, timeout=40)
                yield LookAtCheck(ros, NODE, installed_description(PKG)), control
        finally:
            if node is not None:
                node.stop()
            if control is not None:
                control.close()
            sim.stop()


def test_look_at_straight_ahead(rig):
    check, _ = rig
    check.look_and_reach(0.0, 0.0)


def test_look_at_to_the_left(rig):
    check, control = rig
    check.look_and_reach(math.pi / 2, 0.0)
    assert control.state()["axes"]["yaw"]["position"] == pytest.approx(90.0, abs=1.0)


def test_look_at_up(rig):
    check, control = rig
    check.look_and_reach(0.0, 0.5)
    assert control.state()["axes"]["pitch"]["position"] == pytest.approx(
        math.degrees(0.5), abs=1.0)


def test_look_at_beyond_the_pitch_limit_is_refused_and_sends_nothing(rig):
    check, control = rig
    check.refused(check.point_for(0.0, -1.2), "position_min",
                  device_commands=lambda: control.state()["commands_received"])


def test_look_at_in_another_frame_is_refused(rig):
    check, control = rig
    check.refused(check.point_for(0.0, 0.0), "transform the point first", frame="map",
                  device_commands=lambda: control.state()["commands_received"])
