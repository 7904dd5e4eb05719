"""`TurretDevice` run by gimbal_driver_common's controller against the simulator, no ROS.

The simulator serves slcan on a pseudo-terminal in this process (the node's transport on
this machine) and the adapter opens it with python-can's slcan interface; the controller
supervises the link, queues commands, runs the jog watchdog and the move/preset policies
exactly as it does inside the node.
"""

from __future__ import annotations

import logging
import math
import threading

import pytest

from canaero_turret_driver.client import ClientConfig, CommandError, TurretClient
from canaero_turret_driver.device import TurretDevice, TurretSettings
from canaero_turret_driver.protocol.identifiers import STOP_PITCH_BIT, ActuatorMode
from canaero_turret_driver.sim import YAW, SimConfig, SlcanSession, TurretSimulator
from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.errors import DeviceRefused, GimbalError, InvalidRequest
from gimbal_driver_common.policies import Motion
from gimbal_driver_common.presets import PresetStore
from gimbal_driver_common.sim_server import PtySimServer
from gimbal_driver_testing import wait_for

LOG = logging.getLogger("test_device")
JOINTS = ["yaw", "pitch"]


class Rig:
    """Simulator on a pty, adapter, controller and policies; closed in reverse order."""

    def __init__(self, tmp_path, config: ControllerConfig,
                 settings: TurretSettings | None = None) -> None:
        self.simulator = TurretSimulator(SimConfig())
        self.link = PtySimServer(lambda: SlcanSession(self.simulator),
                                 link_path=str(tmp_path / "tty")).start()
        self.samples = 0
        self.config = config
        # node_timeout: silence that counts as a lost link. 0.6 s was shorter than the
        # simulator thread's worst stall under the parallel suite (a move failed with
        # "turret node 1 silent for 0.6 s"); the silence tests wait for it anyway.
        client_config = ClientConfig(interface="slcan", channel=self.link.port_name,
                                     bus_options={"sleep_after_open": 0},
                                     service_timeout=0.3, node_timeout=2.0, stale_timeout=0.6)
        self.device = TurretDevice(TurretClient(client_config), settings or TurretSettings(),
                                   lambda: self.config.publish_rate, LOG)
        self.controller = GimbalController(self.device, self.config, LOG,
                                           on_sample=self._count)
        self.motion = Motion(self.controller, PresetStore(str(tmp_path / "presets.yaml")))

    def _count(self, sample) -> None:
        self.samples += 1

    def start(self) -> Rig:
        self.controller.open()
        self.controller.activate()
        return self

    def close(self) -> None:
        self.controller.shutdown()
        self.link.stop()

    def sim_axis(self, axis: str) -> dict:
        return self.simulator.state()["axes"][axis]

    def commands_received(self) -> int:
        return self.simulator.state()["commands_received"]

    def move(self, targets: dict[str, float], relative: bool = False):
        resolved = self.motion.start_move(list(targets), list(targets.values()),
                                          relative=relative)
        return self.motion.wait_move(resolved)


@pytest.fixture
def rig(tmp_path, controller_config):
    rig = Rig(tmp_path, controller_config()).start()
    yield rig
    rig.close()


def test_connect_identity_and_streamed_samples(rig):
    info = rig.controller.device_info
    assert info.model == "CANaerospace turret" and info.serial_number == "node 1"
    assert info.firmware_version == "hw 2 sw 7"
    assert info.hardware_id == f"canaerospace node 1 on slcan:{rig.link.port_name}"
    # TIS at connect: positions and velocities every 1/publish_rate
    intervals = rig.simulator.state()["intervals_ms"]
    assert intervals["yaw_position"] == intervals["pitch_velocity"] == 20
    assert rig.device.expected_rate(50.0) == pytest.approx(50.0)
    assert rig.device.expected_rate(10.0) == pytest.approx(10.0)  # never above publish_rate
    wait_for(lambda: rig.samples >= 10, 30, "joint samples from the broadcasts")
    # the currents come every 200 ms (not asked for by TIS), after the first positions
    sample = wait_for(lambda: (latest := rig.controller.latest) is not None
                      and set(latest.currents) == set(JOINTS) and latest, 30,
                      "a sample with both motor currents")
    assert set(sample.positions) == set(JOINTS)
    assert sample.currents["yaw"] > 0.0  # motor current, A
    assert sample.moving == {"yaw": False, "pitch": False}  # status bytes: target reached


def test_a_reader_that_stands_still_is_not_taken_for_a_silent_turret(rig, monkeypatch):
    """The reader stands still inside a take (the sample lock held, the device thread
    waiting on it: a publish that blocks, a core that runs something else) for 2.5
    node_timeouts. It heard nothing because it did not listen: the turret is not judged
    silent meanwhile, and the link stays up once the reader reads on
    (``TurretClient.silent_for``). Judged up to now, a 5 s stall on a loaded pinned core
    dropped the link with "turret node 1 silent for 5.7 s (no CAN frames ...)"."""
    client = rig.device.client
    client.config.node_timeout = 1.0
    wait_for(lambda: rig.samples >= 10, 30, "samples from the broadcasts")
    read, parked, release = rig.device.read, threading.Event(), threading.Event()

    def read_on_a_stalled_reader():
        if threading.current_thread().name == "canaero-reader" and not parked.is_set():
            parked.set()
            release.wait(30)
        return read()

    monkeypatch.setattr(rig.device, "read", read_on_a_stalled_reader)
    assert parked.wait(30), "the reader never took a sample"
    try:
        release.wait(2.5 * client.config.node_timeout)  # the stall: longer than the timeout
        assert not client.node_silent()
    finally:
        release.set()
    seen = rig.samples
    wait_for(lambda: rig.samples >= seen + 10, 30, "samples after the stall")
    assert rig.controller.connected, rig.controller.link_error
    assert client.counters.reconnects == 0
    # the same client still finds a turret that is silent while it listens
    rig.simulator.set_silent("turret")
    wait_for(lambda: not rig.controller.connected, 30, "the silent turret to drop the link")
    assert "turret node 1 silent for" in rig.controller.link_error


def test_move_converges_in_si_units(rig):
    outcome = rig.move({"yaw": 0.4, "pitch": 0.2})
    assert outcome.success, outcome.message
    assert outcome.positions == pytest.approx([0.4, 0.2], abs=0.011)
    assert rig.sim_axis("yaw")["position"] == pytest.approx(math.degrees(0.4), abs=0.01)
    assert rig.sim_axis("pitch")["position"] == pytest.approx(math.degrees(0.2), abs=0.01)
    assert rig.controller.commanded_targets == {"yaw": 0.4, "pitch": 0.2}


def test_units_convert_once_in_the_adapter(rig):
    """The client hands on what the bus carried, in the ICD's units (degrees); the adapter
    alone converts it to SI (radians) and REP-103, for the controller and the readings."""
    outcome = rig.move({"yaw": 0.4, "pitch": 0.2})
    assert outcome.success, outcome.message
    wait_for(lambda: abs(rig.controller.positions()["yaw"] - 0.4) < 0.011, 10, "yaw there")
    raw = rig.device.client.latest("yaw_position")
    assert raw.value == pytest.approx(math.degrees(0.4), abs=0.6)  # degrees on the wire
    assert not hasattr(raw, "si")
    assert rig.device.read().positions["yaw"] == pytest.approx(math.radians(raw.value),
                                                               abs=0.011)


def test_a_setpoint_outside_the_icd_range_is_refused_by_the_adapter(rig):
    """-180..180 degrees (6.1.2): checked in the adapter, in SI, before any frame."""
    before = rig.commands_received()
    with pytest.raises(CommandError, match="outside the device range"):
        rig.device.move({"yaw": (4.0, None)})
    with pytest.raises(CommandError, match="outside the device range"):
        rig.device.move({"pitch": (0.1, None), "yaw": (-4.0, None)})
    assert rig.commands_received() == before


def test_relative_move_goes_out_as_the_relative_setpoint(rig):
    assert rig.move({"yaw": 0.3}).success
    outcome = rig.move({"yaw": -0.1}, relative=True)
    assert outcome.success and outcome.positions[0] == pytest.approx(0.2, abs=0.011)
    key, value = rig.simulator.state()["recent_commands"][-1]
    assert key == "yaw_relative_setpoint" and value == pytest.approx(math.degrees(-0.1))


def test_jog_is_stopped_by_the_watchdog(rig):
    rig.controller.command(["pitch"], [], [0.2])
    wait_for(lambda: rig.sim_axis("pitch")["velocity"] > 5.0, 30, "the pitch jog")
    wait_for(lambda: rig.controller.moving("pitch"), 30, "the status byte to say jog")
    # no further joint_command: the dead-man watchdog stops the axis
    wait_for(lambda: rig.sim_axis("pitch")["velocity"] == 0.0, 30, "the watchdog stop")
    assert rig.controller.watchdog.jogging == []
    key, value = rig.simulator.state()["recent_commands"][-1]
    assert key == "stop_actuators" and int(value) & STOP_PITCH_BIT


def test_stop_halts_every_axis(rig):
    rig.controller.command(["yaw", "pitch"], [], [0.3, -0.2])
    wait_for(lambda: rig.sim_axis("yaw")["velocity"] != 0.0
             and rig.sim_axis("pitch")["velocity"] != 0.0, 30, "both axes to jog")
    assert "stopped" in rig.controller.stop()
    wait_for(lambda: rig.sim_axis("yaw")["velocity"] == 0.0
             and rig.sim_axis("pitch")["velocity"] == 0.0, 30, "both axes to stop")


def test_refusal_names_the_faulted_axis_and_sends_nothing(rig):
    rig.simulator.set_axis_fault("yaw")
    wait_for(lambda: rig.controller.refusal(["yaw"]), 30, "the fault in the status byte")
    reason = rig.controller.refusal(["yaw"])
    assert "'yaw': drive disabled (fault), status byte 0x" in reason
    assert rig.controller.refusal(["pitch"]) is None
    before = rig.commands_received()
    with pytest.raises(DeviceRefused, match="drive disabled"):
        rig.motion.start_move(["yaw"], [0.3])
    with pytest.raises(DeviceRefused, match="yaw"):
        rig.motion.goto_preset(0, 0.0)
    with pytest.raises(DeviceRefused, match="yaw"):
        rig.controller.command(["yaw"], [], [0.2])
    assert rig.commands_received() == before
    with pytest.raises(InvalidRequest, match="outside"):
        rig.motion.start_move(["pitch"], [2.0])  # limits: nothing sent either
    assert rig.commands_received() == before
    assert "re-initialise" in rig.controller.reset_faults()
    wait_for(lambda: rig.controller.refusal(["yaw"]) is None, 30, "the drive to come back")
    assert rig.move({"yaw": 0.3}).success


def test_link_drop_then_reconnect(rig):
    wait_for(lambda: rig.samples > 0, 30, "joint samples")
    rig.link.drop_link(0.5)
    wait_for(lambda: not rig.controller.connected, 30, "the link loss to be seen")
    assert rig.controller.link_error.startswith("link lost")
    with pytest.raises(DeviceRefused, match="not connected"):
        rig.motion.start_move(["yaw"], [0.1])
    wait_for(lambda: rig.controller.connected, 30, "the supervisor to reconnect")
    assert rig.controller.reconnects >= 1
    assert rig.device.client.counters.reconnects >= 1  # the interface was reopened
    before = rig.samples
    wait_for(lambda: rig.samples > before, 30, "joint samples after the reconnect")
    assert rig.move({"yaw": 0.1}).success


def test_turret_silence_is_a_lost_link_until_it_talks_again(rig):
    wait_for(lambda: rig.samples > 0, 30, "joint samples")
    rig.simulator.set_silent("turret")
    wait_for(lambda: not rig.controller.connected, 30, "the silence to be seen")
    assert "turret node 1 silent" in rig.controller.link_error
    # the cover, GNSS and zoom nodes keep talking: the bus is not silent, only the turret
    assert "other CAN frames arrived meanwhile" in rig.controller.link_error
    rig.simulator.set_silent("turret", 0)
    wait_for(lambda: rig.controller.connected, 30, "the supervisor to reconnect")
    assert rig.move({"pitch": 0.1}).success


def test_rep103_direction_applies_both_ways(tmp_path, controller_config):
    """yaw_direction -1: the device counts yaw the other way than REP-103."""
    rig = Rig(tmp_path, controller_config(), TurretSettings(yaw_direction=-1)).start()
    try:
        assert rig.move({"yaw": 0.25}).success  # REP-103 +0.25 rad = device -14.3 deg
        assert rig.sim_axis("yaw")["position"] == pytest.approx(-math.degrees(0.25), abs=1e-3)
        assert rig.controller.positions()["yaw"] == pytest.approx(0.25, abs=1e-3)
        rig.controller.command(["yaw"], [], [0.1])
        wait_for(lambda: rig.sim_axis("yaw")["velocity"] < -5.0, 30, "the device to jog -")
        wait_for(lambda: rig.controller.latest.velocities["yaw"] > 0.09, 30,
                 "a positive REP-103 velocity")
        rig.controller.stop()
        rig.move({"yaw": 0.1}, relative=True)
        key, value = rig.simulator.state()["recent_commands"][-1]
        assert key == "yaw_relative_setpoint" and value == pytest.approx(-math.degrees(0.1))
    finally:
        rig.close()


def test_preset_zero_is_the_turrets_own_the_rest_yaml(rig):
    assert rig.move({"yaw": 0.3, "pitch": 0.1}).success
    assert "remembered" in rig.motion.set_preset(0, "", None)
    wait_for(lambda: rig.simulator.state()["saved_position"] is not None, 30, "remember")
    with pytest.raises(InvalidRequest, match="preset 0"):
        rig.motion.set_preset(0, "", {"yaw": 0.1})
    assert "stored" in rig.motion.set_preset(3, "gate", {"yaw": -0.3, "pitch": 0.0})
    assert [p.index for p in rig.motion.list_presets()] == [0, 3]
    rig.motion.goto_preset(3, 0.0)
    wait_for(lambda: abs(rig.sim_axis("yaw")["position"] + math.degrees(0.3)) < 0.1, 30,
             "preset 3")
    with pytest.raises(InvalidRequest, match="no speed"):
        rig.motion.goto_preset(0, 0.5)
    assert "saved position" in rig.motion.goto_preset(0, 0.0)
    assert rig.controller.commanded_targets["yaw"] == pytest.approx(0.3, abs=0.011)
    wait_for(lambda: abs(rig.sim_axis("yaw")["position"] - math.degrees(0.3)) < 0.1, 30,
             "preset 0 (restore)")
    assert "cannot be erased" in rig.motion.clear_preset(0)
    assert [p.index for p in rig.motion.list_presets()] == [3]


def test_extras_modes_switches_and_node_services(rig):
    call = rig.controller.call
    assert call(lambda: rig.device.set_mode("yaw=free_run")) == "actuator mode yaw=free_run"
    wait_for(lambda: rig.sim_axis("yaw")["actuator_mode"] == 0, 30, "free run")
    before = rig.commands_received()
    with pytest.raises(InvalidRequest, match="auto_brake"):
        call(lambda: rig.device.set_mode("pitch=warp"))
    with pytest.raises(InvalidRequest, match="unknown joint"):
        call(lambda: rig.device.set_mode("roll=auto_brake"))
    assert rig.commands_received() == before
    call(lambda: rig.device.set_mode("auto_brake"))
    wait_for(lambda: rig.sim_axis("yaw")["actuator_mode"] == 2, 30, "auto brake")
    assert call(lambda: rig.device.switch("set_cover", True)) == "cover opening"
    assert call(lambda: rig.device.switch("set_fan", True)) == "fan on"
    wait_for(lambda: rig.simulator.state()["cover_state"] == 1, 30, "the cover to open")
    message, results = call(lambda: rig.device.node_services.device_command("identify", []))
    assert message == "IDS answered" and "software_revision=7" in results
    with pytest.raises(DeviceRefused, match="allow_node_id_change"):
        call(lambda: rig.device.node_services.device_command("set_node_id", ["9"]))
    with pytest.raises(DeviceRefused, match="allow_data_download"):
        call(lambda: rig.device.node_services.device_command("download", ["1", "0102"]))
    with pytest.raises(DeviceRefused, match="out of range"):  # the node's TIS refusal
        call(lambda: rig.device.node_services.device_command("set_interval",
                                                             ["case_temperature", "5"]))
    with pytest.raises(InvalidRequest, match="unknown command"):
        call(lambda: rig.device.node_services.device_command("format_disk", []))
    assert rig.simulator.state()["node_ids"]["turret"] == 1


def test_configured_actuator_mode_goes_only_to_an_axis_not_reporting_it(tmp_path,
                                                                     controller_config):
    """A mode command re-initialises a drive (stopping its move), so activation leaves an
    axis that already reports the configured mode alone."""
    rig = Rig(tmp_path, controller_config(), TurretSettings(actuator_mode="auto_brake"))
    rig.simulator.axes[YAW].actuator_mode = ActuatorMode.WITHOUT_BRAKE
    try:
        rig.start()
        wait_for(lambda: rig.samples > 0, 30, "joint samples")
        answer = rig.controller.call(rig.device.apply_actuator_mode)
        assert answer == "actuator mode auto_brake sent to yaw; already reported by pitch"
        wait_for(lambda: rig.sim_axis("yaw")["actuator_mode"] == 2, 30, "yaw in auto brake")
        modes = [key for key, _ in rig.simulator.state()["recent_commands"]
                 if key.endswith("_actuator_mode")]
        assert modes == ["yaw_actuator_mode"]
        wait_for(lambda: rig.device.reported_mode("yaw") == ActuatorMode.AUTO_BRAKE, 30,
                 "yaw to report auto brake")
        before = rig.commands_received()
        assert rig.controller.call(rig.device.apply_actuator_mode) == (
            "already reported by yaw, pitch")
        assert rig.commands_received() == before
    finally:
        rig.close()


def test_readings_are_handed_out_once_per_frame(rig):
    fixes = []
    readings = rig.device.readings
    wait_for(lambda: fixes.append(readings.new_fix()) or fixes[-1] is not None, 30, "a fix")
    assert fixes[-1].latitude == pytest.approx(48.1372) and fixes[-1].fresh
    assert rig.device.readings.new_fix() is None  # same frame: not again
    wait_for(lambda: rig.device.readings.new_heading("rover_heading") is not None, 30, "a heading")
    heading = None

    def next_heading():
        nonlocal heading
        heading = rig.device.readings.new_heading("global_yaw")
        return heading

    wait_for(lambda: next_heading() is not None and heading.accuracy is not None, 30,
             "a global yaw with its accuracy")
    assert heading.heading == pytest.approx(math.radians(123.45678), abs=1e-6)
    assert heading.accuracy == pytest.approx(math.radians(0.25))
    assert rig.device.readings.new_heading("global_yaw") is None  # same frame: not again
    assert rig.device.readings.zoom() == 2500.0
    inclination = rig.device.readings.inclination()
    assert inclination.roll == pytest.approx(math.radians(-0.8), abs=1e-4)


def test_status_report_decodes_the_turret(rig):
    report = rig.device.capabilities.status
    wait_for(lambda: "auto_brake" in report.mode(), 30, "the actuator modes")
    parts = {p.part: p for p in report.parts()}
    assert {"turret node", "yaw", "pitch", "periphery", "message codes", "emergency events",
            "data freshness", "transmission intervals"} <= set(parts)
    assert dict(parts["turret node"].values)["turret_node_id"] == "1"
    rig.simulator.set_axis_fault("pitch")
    wait_for(lambda: "pitch_drive_disabled" in report.errors(), 30, "the fault")
    assert report.axis_details("pitch")["active_errors"] == ["drive_disabled"]


def test_bus_errors_drop_the_link_and_the_controller_reopens_it(channel_name, simulator,
                                                               flaky_bus, supervised):
    """A failing adapter, then a bus-off: the client drops the bus each time and the
    controller's supervisor (the only one) reopens it."""
    faults: list[str] = []
    links: list[tuple[bool, str]] = []
    config = ClientConfig(interface="virtual", channel=channel_name, service_timeout=0.5)
    client = TurretClient(config, bus_factory=lambda cfg: flaky_bus(cfg.channel, faults))
    with supervised(client, reconnect_period=0.05) as controller:
        wake = client.on_link
        client.on_link = lambda up, why: (links.append((up, why)), wake(up, why))
        for fault, count in (("raise", 1), ("busoff", 2)):
            wait_for(lambda: controller.latest is not None, 30, "joint samples")
            faults.append(fault)
            wait_for(lambda c=count: controller.reconnects >= c and controller.connected, 30,
                     f"the supervisor to reopen the interface after {fault}")
        assert client.counters.reconnects >= 2
        assert client.counters.bus_errors >= 1
        assert any("bus-off" in why for up, why in links if not up)
        assert any("adapter unplugged" in why for up, why in links if not up)
        wait_for(lambda: not client.is_stale("yaw_position"), 30, "data after reopening")
        assert client.services.identify().software_revision == 7


def test_an_unanswered_ids_never_keeps_the_turret_from_connecting(tmp_path, controller_config,
                                                                 caplog):
    """IDS is identification only: unanswered while the turret broadcasts, it is a WARN and
    a diagnostics key, the node connects and the turret moves."""
    rig = Rig(tmp_path, controller_config())
    rig.simulator.request_faults.mute("IDS")
    with caplog.at_level(logging.WARNING):
        rig.start()
    try:
        assert "IDS unanswered" in caplog.text
        assert "IDS unanswered" in rig.controller.device_info.firmware_version
        node = next(p for p in rig.device.capabilities.status.parts()
                    if p.part == "turret node")
        assert node.level == 1 and "unanswered.IDS" in dict(node.values), node
        assert rig.move({"yaw": 0.2}).success
    finally:
        rig.close()


def test_an_unanswered_ids_from_a_silent_turret_names_both(tmp_path, controller_config):
    rig = Rig(tmp_path, controller_config())
    rig.simulator.request_faults.mute("IDS")
    rig.simulator.silence_all()
    try:
        with pytest.raises(GimbalError, match=r"no IDS response.*no broadcast from turret node"):
            rig.controller.open()
    finally:
        rig.close()
