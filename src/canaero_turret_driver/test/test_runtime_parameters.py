"""Turret parameters changed while the node runs (`ros2 param set`), node against the
simulator (slcan over a pty): TIS transmission intervals go to the turret at once.
"""

from __future__ import annotations

import json

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from sensor_msgs.msg import JointState

from canaero_turret_driver.sim import ControlClient
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.ros import driver_rig

pytestmark = pytest.mark.ros

PKG = "canaero_turret_driver"
NODE = "canaero_turret_driver"
FAST = ["yaw_position=20", "pitch_position=20"]


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("canaero_params")
    tty, ready = tmp / "tty", tmp / "ready.json"
    with driver_rig(PKG, "canaero_turret_sim", ["--link", str(tty), "--ready-file", str(ready)],
                    lambda _: wait_for(ready.exists, 20, "the simulator to start"),
                    "canaero_turret_driver_node", [
                        "can_interface:=slcan", f"can_channel:={tty}",
                        "can_options:=['sleep_after_open=0']", "service_timeout:=0.3",
                        "reconnect_period:=0.3", "publish_rate:=100.0",
                        "transmission_intervals:=['yaw_position=20','pitch_position=20']"],
                    ) as rig:
        control = ControlClient(json.loads(ready.read_text())["control_port"])
        try:
            yield rig.ros, control, rig.node
        finally:
            control.close()


def test_transmission_intervals_go_to_the_turret_when_set(rig) -> None:
    ros, control, _ = rig
    assert control.state()["intervals_ms"]["yaw_position"] == 20
    slow = ["yaw_position=400", "pitch_position=400"]
    result = ros.set_parameter(NODE, "transmission_intervals", slow)
    assert result.successful, result.reason
    intervals = control.state()["intervals_ms"]
    assert intervals["yaw_position"] == 400 and intervals["pitch_position"] == 400
    ros.mean_stamp_gap("joint_states", JointState, 1)  # let a sample of the old rate pass
    # One yaw and one pitch frame per 0.4 s; each new one may publish: >= 0.2 s apart.
    assert ros.mean_stamp_gap("joint_states", JointState, 6) >= 0.15
    assert ros.set_parameter(NODE, "transmission_intervals", FAST).successful
    assert control.state()["intervals_ms"]["yaw_position"] == 20
    ros.mean_stamp_gap("joint_states", JointState, 1)
    assert ros.mean_stamp_gap("joint_states", JointState, 20) < 0.1  # 20 ms cycles


def test_invalid_intervals_are_refused_and_nothing_changes(rig) -> None:
    ros, control, _ = rig
    refused = ros.set_parameter(NODE, "transmission_intervals", ["yaw_heading=20"])
    assert not refused.successful and "identifier table" in refused.reason  # start-up check
    refused = ros.set_parameter(NODE, "transmission_intervals", ["yaw_position=fast"])
    assert not refused.successful and "integer number of ms" in refused.reason
    # The node passes the value; the turret refuses it (TIS range 10..10000 ms).
    refused = ros.set_parameter(NODE, "transmission_intervals", ["yaw_position=5"])
    assert not refused.successful, refused.reason
    assert "device refused" in refused.reason and "TIS" in refused.reason, refused.reason
    assert control.state()["intervals_ms"]["yaw_position"] == 20
    assert ros.get_parameter(NODE, "transmission_intervals") == FAST


def test_other_turret_parameters(rig) -> None:
    ros, _, _ = rig
    assert ros.set_parameter(NODE, "temperature_warn", 60.0).successful
    refused = ros.set_parameter(NODE, "temperature_warn", 500.0)  # range -50..200 degC
    assert not refused.successful and "temperature_warn" in refused.reason
    for name, value in (("turret_node_id", 9), ("allow_flash_programming", True),
                        ("can_channel", "can1")):
        refused = ros.set_parameter(NODE, name, value)
        assert not refused.successful and "needs reconfigure" in refused.reason, name
