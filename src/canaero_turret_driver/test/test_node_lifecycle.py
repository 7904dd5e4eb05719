"""Managed bring-up, start-up parameter checks and the opt-in node services, as processes."""

from __future__ import annotations

import time

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from sensor_msgs.msg import JointState

from gimbal_driver_testing import DomainLease, ManagedProcess, ros_arguments
from gimbal_driver_testing.ros import RosTestClient, node_refusing_to_start
from gimbal_msgs.srv import DeviceCommand

pytestmark = pytest.mark.ros

PKG = "canaero_turret_driver"
NODE = "canaero_turret_driver"


@pytest.mark.parametrize(("param", "expected"), [
    ("transmission_intervals:=['bogus=5']", "transmission_intervals"),
    ("yaw_direction:=0", "yaw_direction"),
    ("actuator_mode:=sideways", "actuator_mode"),
    ("can_options:=['novalue']", "can_options"),
    ("service_channel:=50", "service_channel"),
    ("transfer_first_number:=2", "transfer_first_number"),
])
def test_invalid_parameters_are_refused_at_start(param, expected):
    output = node_refusing_to_start(PKG, "canaero_turret_driver_node",
                                    ["can_interface:=virtual", param])
    assert expected in output


@pytest.fixture(scope="module")
def managed(tmp_path_factory, sim_and_node):
    params = ["can_options:=['sleep_after_open=0']",
              "service_timeout:=0.3", "reconnect_period:=0.3", "command_timeout:=5.0",
              "allow_node_id_change:=true", "allow_flash_programming:=true",
              "allow_data_download:=true", "can_interface:=slcan",
              "transfer_first_number:=1"]  # DDS/DUS numbered from 1 on both sides
    with sim_and_node(tmp_path_factory.mktemp("canaero_managed"),
                      lambda tty: [*params, f"can_channel:={tty}"],
                      ["--transfer-first-number", "1"]) as rig:
        yield rig




def call(ros, command, *arguments):
    request = DeviceCommand.Request(command=command, arguments=list(arguments))
    return ros.call(DeviceCommand, f"/{NODE}/device_command", request)


def test_opt_in_services_when_enabled(managed):
    ros, control, _ = managed
    ros.wait_for_lifecycle_state(NODE, "active")
    reply = call(ros, "download", "1", "00112233445566")
    assert reply.success, reply.message
    assert call(ros, "upload", "1", "7").results == ["00112233445566"]
    reply = call(ros, "store_configuration", "0x11")
    assert not reply.success and "invalid security code" in reply.message
    reply = call(ros, "store_configuration", "0x5A")
    assert reply.success, reply.message
    assert control.state()["stored_configuration"]
    reply = call(ros, "set_node_id", "300")
    assert not reply.success and "1..199" in reply.message
    reply = call(ros, "set_node_id", "9")
    assert reply.success, reply.message
    assert control.state()["node_ids"]["turret"] == 9
    # The driver follows the new id: data keeps flowing and IDS reaches node 9.
    start = time.time()
    ros.wait_for_message("joint_states", JointState,
                         lambda m: m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 > start,
                         timeout=20)
    reply = call(ros, "identify")
    assert reply.success and "software_revision=7" in reply.results


def test_node_waits_for_an_absent_device_then_connects(tmp_path):
    tty, ready = tmp_path / "tty", tmp_path / "ready.json"
    with DomainLease() as domain:
        node = ManagedProcess.ros(PKG, "canaero_turret_driver_node", domain, ros_arguments([
            "can_interface:=slcan", f"can_channel:={tty}",
            "can_options:=['sleep_after_open=0']", "reconnect_period:=0.3",
            "service_timeout:=0.3"]))
        sim = None
        ros = RosTestClient(domain)
        try:
            out = node.wait_for_output("configure failed", timeout=30)
            assert "cannot open CAN interface slcan" in out
            sim = ManagedProcess.ros(PKG, "canaero_turret_sim", domain,
                                     ["--link", str(tty), "--ready-file", str(ready)])
            ros.wait_for_message("joint_states", JointState, timeout=40)
            ros.wait_for_lifecycle_state(NODE, "active")
        finally:
            ros.close()
            node.stop()
            if sim is not None:
                sim.stop()
