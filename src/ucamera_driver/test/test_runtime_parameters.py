"""U-Camera parameters changed while the node runs (`ros2 param set`), node against
ucamera_sim over a pseudo-terminal: telemetry_rate goes to the gimbal at once.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

pytest.importorskip("rclpy")
pytest.importorskip("gimbal_msgs", reason="needs the built workspace: make build; "
                    "source scripts/ros_env.sh")

from sensor_msgs.msg import JointState  # noqa: E402

from gimbal_driver_testing.ros import driver_rig  # noqa: E402

NODE = "ucamera_driver"


@pytest.fixture(scope="module")
def rig():
    with tempfile.TemporaryDirectory(prefix="ucamera-params-") as tmp:
        link = str(Path(tmp, "tty"))
        with driver_rig("ucamera_driver", "ucamera_sim", ["--link", link, "--init-time", "0.1"],
                        link, "ucamera_driver_node",
                        [f"serial_port:={link}", "reconnect_period:=0.3", "telemetry_rate:=50"],
                        client_name="ucamera_params_client") as rig:
            yield rig.ros, rig.node


def test_telemetry_rate_is_sent_to_the_gimbal_when_set(rig) -> None:
    ros, node = rig
    result = ros.set_parameter(NODE, "telemetry_rate", 4)
    assert result.successful, result.reason
    ros.mean_stamp_gap("joint_states", JointState, 1)  # let a report of the old rate pass
    assert ros.mean_stamp_gap("joint_states", JointState, 4) >= 0.2  # 4 Hz: 0.25 s apart
    result = ros.set_parameter(NODE, "telemetry_rate", 50)
    assert result.successful, result.reason
    ros.mean_stamp_gap("joint_states", JointState, 1)
    assert ros.mean_stamp_gap("joint_states", JointState, 20) < 0.15  # 50 Hz: 0.02 s apart
    node.wait_for_output("parameter 'telemetry_rate' set to 50")


def test_invalid_and_fixed_parameters_are_refused(rig) -> None:
    ros, _ = rig
    refused = ros.set_parameter(NODE, "telemetry_rate", 500)  # UCSP: 1..200 Hz
    assert not refused.successful and "telemetry_rate" in refused.reason
    refused = ros.set_parameter(NODE, "refresh_rate", 0.5)  # manual mode needs >= 1 Hz
    assert not refused.successful and "refresh_rate" in refused.reason
    assert ros.get_parameter(NODE, "telemetry_rate") == 50
    refused = ros.set_parameter(NODE, "invert_pan", False)
    assert not refused.successful and "read-only" in refused.reason
    refused = ros.set_parameter(NODE, "allow_nv_write", True)
    assert not refused.successful and "read-only" in refused.reason
    refused = ros.set_parameter(NODE, "baudrate", 57600)
    assert not refused.successful and "needs reconfigure" in refused.reason
    assert ros.set_parameter(NODE, "refresh_rate", 20.0).successful
    assert ros.set_parameter(NODE, "report_publish_rate", 5.0).successful
