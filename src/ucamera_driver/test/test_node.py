"""The node and the simulator as separate processes, checked through rclpy.

Needs the colcon-built workspace (``make build`` then ``source scripts/ros_env.sh``).
The simulator runs with short durations and takes the shared control verbs on its
TCP console (``--control-port``); its ``state`` answer shows the device-frame
angles, which checks the REP-103 sign conversion (device pan is negated).
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("gimbal_msgs", reason="needs the built workspace: make build; "
                    "source scripts/ros_env.sh")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import TwistStamped  # noqa: E402
from lifecycle_msgs.msg import Transition  # noqa: E402
from sensor_msgs.msg import Imu, JointState, NavSatFix, NavSatStatus  # noqa: E402
from std_msgs.msg import Float64, UInt16  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from gimbal_driver_common.sim_control import control_request, control_state  # noqa: E402
from gimbal_driver_testing import (  # noqa: E402
    DomainLease,
    ManagedProcess,
    wait_for,
    wait_for_ready,
)
from gimbal_driver_testing.ros import RosTestClient, node_refusing_to_start  # noqa: E402
from gimbal_msgs.action import Home, MoveTo  # noqa: E402
from gimbal_msgs.msg import GimbalStatus  # noqa: E402
from gimbal_msgs.srv import (  # noqa: E402
    ClearPreset,
    GotoPreset,
    ListPresets,
    SetMode,
    SetPreset,
    StartScan,
)

NODE = "ucamera_driver"
SIM_ARGS = ["--init-time", "0.1", "--max-rate", "180", "--acceleration", "1800",
            "--autoalign-time", "0.3", "--ffc-time", "0.3", "--save-pause", "0.5"]
GOAL_SUCCEEDED = 4
GOAL_ABORTED = 6


class Rig:
    """Simulator process + node process + a ROS test client in one leased domain."""

    def __init__(self, node_params: dict[str, str], params_file: str | None = None,
                 wait_active: bool = True) -> None:
        self.lease = DomainLease()
        domain = self.lease.acquire()
        self.tmp = tempfile.TemporaryDirectory(prefix="ucamera-node-test-")
        self.link = str(Path(self.tmp.name, "tty"))
        self.sim = ManagedProcess.ros("ucamera_driver", "ucamera_sim", domain,
                                      ["--link", self.link, *SIM_ARGS])
        self.control_port = wait_for_ready(self.sim, "ucamera_sim")["control_port"]
        params = {"serial_port": self.link, "presets_file": f"{self.tmp.name}/presets.yaml",
                  "velocity_max": "[3.0, 3.0]", "reconnect_period": "0.3",
                  "silence_timeout": "1.0", "diagnostics_period": "0.3", **node_params}
        args = ["--ros-args"]
        if params_file:
            args += ["--params-file", params_file]
        for key, value in params.items():
            args += ["-p", f"{key}:={value}"]
        self.node = ManagedProcess.ros("ucamera_driver", "ucamera_driver_node", domain, args)
        self.ros = RosTestClient(domain, name="ucamera_test_client")
        if wait_active:
            self.ros.wait_for_message("joint_states", JointState, timeout=30.0, fresh=False)

    def close(self) -> None:
        self.ros.close()
        self.node.stop()
        self.sim.stop()
        self.tmp.cleanup()
        self.lease.release()

    # simulator control
    def sim_command(self, line: str) -> None:
        answer = control_request(self.control_port, line)
        assert answer.startswith("ok"), answer

    def sim_state(self) -> dict:
        return control_state(self.control_port)

    def device_angles_deg(self) -> tuple[float, float]:
        axes = self.sim_state()["axes"]
        return math.degrees(axes["pan"]["position"]), math.degrees(axes["tilt"]["position"])

    # ROS helpers
    def joints(self, predicate, timeout: float = 15.0) -> JointState:
        return self.ros.wait_for_message("joint_states", JointState, predicate, timeout)

    def publish_until(self, topic: str, msg, condition, timeout: float = 15.0,
                      what: str = "") -> object:
        """Publish ``msg`` every 0.1 s until ``condition()`` holds.

        A single publish right after discovery can be lost (volatile QoS), so
        idempotent commands are repeated until their effect is seen.
        """
        def attempt() -> object:
            self.ros.publish(topic, msg)
            time.sleep(0.1)
            return condition()

        return wait_for(attempt, timeout, what or f"the effect of a message on {topic}")

    def command(self, names, positions=(), velocities=(), until=None, what: str = "") -> None:
        """Publish a joint_command until ``until(joint_states message)`` holds."""
        msg = JointState(name=list(names), position=list(positions),
                         velocity=list(velocities))
        states = self.ros.subscribe("joint_states", JointState)
        start = len(states)
        if until is None:
            until = self.at(*positions) if len(positions) == 2 else (lambda m: True)
        self.publish_until("joint_command", msg,
                           lambda: any(until(m) for m in list(states)[start:]),
                           what=what or f"joint_states after {msg.name}")

    def until_output(self, text: str):
        return lambda _m: text in self.node.output()

    def at(self, pan: float, tilt: float, tol: float = 0.01):
        return lambda m: (len(m.position) == 2 and abs(m.position[0] - pan) < tol
                          and abs(m.position[1] - tilt) < tol)

    def status(self, predicate, timeout: float = 15.0) -> GimbalStatus:
        return self.ros.wait_for_message(f"/{NODE}/status", GimbalStatus, predicate, timeout)

    def diagnostics(self, predicate, timeout: float = 15.0) -> DiagnosticArray:
        return self.ros.wait_for_message("/diagnostics", DiagnosticArray, predicate, timeout)

    def trigger(self, name: str) -> Trigger.Response:
        return self.ros.call(Trigger, f"/{NODE}/{name}", Trigger.Request())


def device_part(array: DiagnosticArray, part: str):
    for status in array.status:
        if status.name == f"{NODE}: {part}":
            return status
    return None


def value(status, key: str) -> str:
    return {kv.key: kv.value for kv in status.values}[key]


@pytest.fixture(scope="module")
def rig() -> Iterator[Rig]:
    setup = Rig({"allow_nv_write": "true", "gps_feed": "external", "command_timeout": "0.5",
                 "ir_palette": "2", "antenna_position": "[0.1, 0.0, -0.25]"})
    try:
        yield setup
    finally:
        setup.close()


def test_joint_states_and_rep103_signs(rig: Rig) -> None:
    msg = rig.joints(None)
    assert list(msg.name) == ["pan", "tilt"]
    rig.command(["pan", "tilt"], [0.5, 0.3])
    # joint_states is within 0.01 rad by now; the gimbal settles on the set-point after it.
    # Device pan counts positive to the right (REP-103's negative), tilt the same way.
    expected = (-math.degrees(0.5), math.degrees(0.3))
    wait_for(lambda: all(abs(angle - want) <= 0.1 for angle, want in
                         zip(rig.device_angles_deg(), expected, strict=True)),
             10.0, "the gimbal at pan -28.65 deg, tilt 17.19 deg (device signs)")
    rig.status(lambda s: s.mode == "angles" and s.connection == GimbalStatus.CONNECTION_CONNECTED)




def test_move_to_with_speed_and_limits(rig: Rig) -> None:
    goal = MoveTo.Goal(joint_names=["pan", "tilt"], positions=[-0.4, 0.2],
                       velocities=[0.8, 0.8])
    result, status, feedback = rig.ros.run_action(MoveTo, f"/{NODE}/move_to", goal)
    assert status == GOAL_SUCCEEDED, result.message
    assert result.positions[0] == pytest.approx(-0.4, abs=0.02)
    assert feedback
    bad = MoveTo.Goal(joint_names=["pan"], positions=[4.0])
    result, status, _ = rig.ros.run_action(MoveTo, f"/{NODE}/move_to", bad)
    assert status == GOAL_ABORTED
    assert "outside" in result.message




def test_home_goes_to_pilot_position(rig: Rig) -> None:
    rig.command(["pan", "tilt"], [0.3, -0.3])
    result, status, _ = rig.ros.run_action(Home, f"/{NODE}/home", Home.Goal())
    assert status == GOAL_SUCCEEDED, result.message
    assert "pilot" in result.message
    rig.joints(rig.at(0.0, 0.0))
    rig.status(lambda s: s.mode == "pilot")


def test_set_mode_every_kind(rig: Rig) -> None:
    reply = rig.ros.call(SetMode, f"/{NODE}/set_mode", SetMode.Request(mode="stow"))
    assert reply.success, reply.message
    rig.joints(rig.at(0.0, math.pi / 2))  # 4.2: stow points tilt +90 (REP-103: up)
    reply = rig.ros.call(SetMode, f"/{NODE}/set_mode", SetMode.Request(mode="warp"))
    assert not reply.success
    assert "ffc_calibration" in reply.message and "stow" in reply.message
    for mode in ("gyro_autoalign", "ffc_calibration"):
        reply = rig.ros.call(SetMode, f"/{NODE}/set_mode", SetMode.Request(mode=mode))
        assert reply.success, reply.message
        rig.status(lambda s: s.mode == "angles")  # returns by itself
    reply = rig.ros.call(SetMode, f"/{NODE}/set_mode", SetMode.Request(mode="rates"))
    assert reply.success, reply.message
    reply = rig.ros.call(SetMode, f"/{NODE}/set_mode", SetMode.Request(mode="angles"))
    assert reply.success, reply.message


def test_zoom_command_and_report(rig: Rig) -> None:
    zooms = rig.ros.subscribe(f"/{NODE}/zoom", Float64)
    rig.publish_until(f"/{NODE}/zoom_command", Float64(data=0.4),
                      lambda: any(abs(m.data - 0.4) < 1e-3 for m in list(zooms)))
    rig.publish_until(f"/{NODE}/zoom_command", Float64(data=1.5),
                      lambda: "zoom_command rejected" in rig.node.output())


def test_ir_palette_and_antenna_position(rig: Rig) -> None:
    rig.ros.wait_for_message(f"/{NODE}/ir_palette", UInt16, lambda m: m.data == 2)
    palettes = rig.ros.subscribe(f"/{NODE}/ir_palette", UInt16)
    rig.publish_until(f"/{NODE}/ir_palette_command", UInt16(data=5),
                      lambda: any(m.data == 5 for m in list(palettes)))
    array = rig.diagnostics(lambda a: device_part(a, "device") is not None)
    assert value(device_part(array, "device"), "antenna_position_m") == "0.100, 0.000, -0.250"


def test_external_feed_reaches_the_gimbal(rig: Rig) -> None:
    velocity = TwistStamped()
    velocity.twist.linear.x = 1.0  # east
    fix = NavSatFix(latitude=12.5, longitude=-45.25, altitude=321.0)
    fix.status.status = NavSatStatus.STATUS_FIX
    imu = Imu()
    imu.orientation.w = 1.0  # facing east, level: NED yaw +90 deg
    fixes = rig.ros.subscribe(f"/{NODE}/fix", NavSatFix)

    def forwarded() -> NavSatFix | None:
        # re-publish: the first messages after discovery may be lost (volatile QoS)
        rig.ros.publish(f"/{NODE}/ext/velocity", velocity)
        rig.ros.publish(f"/{NODE}/ext/fix", fix)
        rig.ros.publish(f"/{NODE}/ext/imu", imu)
        time.sleep(0.1)
        return next((m for m in list(fixes) if abs(m.latitude - 12.5) < 1e-6), None)

    out = wait_for(forwarded, 15.0, "the external fix in ~/fix")
    assert out.longitude == pytest.approx(-45.25)
    assert out.altitude == pytest.approx(321.0)
    wait_for(lambda: (angles := rig.sim_state()["vehicle_angles"]) is not None
             and [round(math.degrees(a), 1) + 0.0 for a in angles] == [90.0, 0.0, 0.0],
             10.0, "vehicle angles")


def test_save_configuration_with_opt_in(rig: Rig) -> None:
    reply = rig.trigger("save_configuration")
    assert reply.success, reply.message
    wait_for(lambda: rig.sim_state()["nv_saves"] == 1, 10.0, "an NV write in the simulator")
    reply = rig.trigger("save_ffc")
    assert reply.success, reply.message
    # the ~1 s pause is not a disconnection
    rig.joints(None)
    rig.status(lambda s: s.connection == GimbalStatus.CONNECTION_CONNECTED)


def test_driver_side_presets_and_scan(rig: Rig) -> None:
    call = rig.ros.call
    reply = call(SetPreset, f"/{NODE}/set_preset", SetPreset.Request(
        index=3, name="left", use_current_position=False, joint_names=["pan", "tilt"],
        positions=[0.6, -0.2]))
    assert reply.success, reply.message
    listed = call(ListPresets, f"/{NODE}/list_presets", ListPresets.Request())
    assert [p.index for p in listed.presets] == [3]
    reply = call(GotoPreset, f"/{NODE}/goto_preset", GotoPreset.Request(index=3, speed=1.0))
    assert reply.success, reply.message
    rig.joints(rig.at(0.6, -0.2))
    reply = call(ClearPreset, f"/{NODE}/clear_preset", ClearPreset.Request(all=True))
    assert reply.success, reply.message
    scan = StartScan.Request(pattern="sector", pan_min=-0.3, pan_max=0.3, tilt_min=0.0,
                             tilt_max=0.0, speed=1.0, tilt_step=0.1, dwell=0.0)
    reply = call(StartScan, f"/{NODE}/start_scan", scan)
    assert reply.success, reply.message
    rig.joints(lambda m: abs(m.position[0] - 0.3) < 0.02)
    rig.joints(lambda m: abs(m.position[0] + 0.3) < 0.02)
    assert rig.trigger("stop_scan").success


def test_diagnostics_report_mode_rate_and_checksum_errors(rig: Rig) -> None:
    for _ in range(5):
        rig.sim_command("noise 300")
    rig.sim_command("corrupt 5")

    def has_errors(array: DiagnosticArray) -> bool:
        part = device_part(array, "device")
        return part is not None and int(value(part, "checksum_errors")) > 0

    array = rig.diagnostics(has_errors)
    part = device_part(array, "device")
    assert value(part, "mode") in ("angles", "rates", "pilot")
    assert float(value(part, "telemetry_rate_achieved_hz")) > 0
    assert int(value(part, "discarded_bytes")) > 0
    connection = device_part(array, "connection")
    assert value(connection, "connected") == "True"
    rig.command(["pan", "tilt"], [0.1, 0.1])


def test_reset_faults_is_a_clear_refusal(rig: Rig) -> None:
    reply = rig.trigger("reset_faults")
    assert not reply.success
    assert "no fault-reset" in reply.message


def test_lifecycle_deactivate_and_activate(rig: Rig) -> None:
    assert rig.ros.lifecycle_transition(NODE, Transition.TRANSITION_DEACTIVATE)
    assert rig.ros.lifecycle_state(NODE) == "inactive"
    reply = rig.trigger("save_configuration")
    assert not reply.success and "not active" in reply.message
    assert rig.ros.lifecycle_transition(NODE, Transition.TRANSITION_ACTIVATE)
    rig.joints(None)


def test_silence_and_link_drop_recovery(rig: Rig) -> None:
    rig.sim_command("silence on")

    def disconnected(array: DiagnosticArray) -> bool:
        part = device_part(array, "connection")
        return part is not None and part.level == bytes([2])

    rig.diagnostics(disconnected)
    rig.sim_command("silence off")
    rig.status(lambda s: s.connection == GimbalStatus.CONNECTION_CONNECTED, timeout=20.0)
    # a jog running when the link drops: the gimbal keeps its last rates, so the
    # node must zero them when it reconnects
    rig.command(["pan"], velocities=[0.3], until=lambda m: m.velocity[0] > 0.2)
    rig.sim_command("drop 0.5")
    rig.status(lambda s: s.connection != GimbalStatus.CONNECTION_CONNECTED)
    connected = rig.status(lambda s: s.connection == GimbalStatus.CONNECTION_CONNECTED,
                           timeout=20.0)
    assert connected.reconnects >= 2
    rig.joints(lambda m: abs(m.velocity[0]) < 1e-3)
    assert "rates set to zero" in rig.node.output()
    rig.command(["pan", "tilt"], [-0.2, 0.0])


def packaged_config(name: str) -> str:
    from ament_index_python.packages import get_package_share_directory

    return str(Path(get_package_share_directory("ucamera_driver"), "config", name))


def test_real_hardware_yaml_loads_and_nv_write_needs_opt_in() -> None:
    setup = Rig({}, params_file=packaged_config("ucamera_driver.yaml"))
    try:
        reply = setup.trigger("save_configuration")
        assert not reply.success
        assert "allow_nv_write" in reply.message
        assert not setup.trigger("save_ffc").success
        assert setup.sim_state()["nv_saves"] == 0
    finally:
        setup.close()


def test_invalid_parameter_is_refused_at_start_up() -> None:
    output = node_refusing_to_start("ucamera_driver", "ucamera_driver_node",
                                    ["telemetry_rate:=500"])
    assert "telemetry_rate" in output


def test_managed_lifecycle_and_configure_failure() -> None:
    setup = Rig({"autostart": "false"}, wait_active=False)
    try:
        ros = setup.ros
        ros.wait_for_lifecycle_state(NODE, "unconfigured")
        assert ros.lifecycle_transition(NODE, Transition.TRANSITION_CONFIGURE)
        assert ros.lifecycle_state(NODE) == "inactive"
        assert setup.trigger("stop").success  # ~/stop works in every state with a link
        assert not setup.trigger("save_configuration").success  # not active: refused
        assert ros.lifecycle_transition(NODE, Transition.TRANSITION_ACTIVATE)
        setup.joints(None)
        assert ros.lifecycle_transition(NODE, Transition.TRANSITION_DEACTIVATE)
        assert ros.lifecycle_transition(NODE, Transition.TRANSITION_CLEANUP)
        # the device disappears: configure fails with a clear log line
        setup.sim.stop()
        assert not ros.lifecycle_transition(NODE, Transition.TRANSITION_CONFIGURE)
        assert ros.lifecycle_state(NODE) == "unconfigured"
        wait_for(lambda: "configure failed: cannot reach the device" in setup.node.output(),
                 10.0, "the configure failure log line")
        assert "did not answer Request Gimbal Version" in setup.node.output()
    finally:
        setup.close()
