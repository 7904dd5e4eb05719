"""GimbalController + UCameraDevice against the simulator over a real pseudo-terminal (no ROS).

The same controller and policies the node runs, in-process: connect and identity,
the REP-103 conversion both ways, moves (with and without a speed ramp), the jog
watchdog, stop, refusals, homing, the device extras and a link drop that the
controller's supervisor (not the client) recovers.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Iterator

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController, is_moving
from gimbal_driver_common.errors import (
    DeviceRefused,
    GimbalError,
    InvalidRequest,
    LinkError,
    Unsupported,
)
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.policies import Motion
from gimbal_driver_testing import wait_for
from ucamera_driver.device import UCameraDevice, UCameraSettings
from ucamera_driver.device_functions import enu_flu_to_ned_frd
from ucamera_driver.protocol import GimbalMode, ZoomReport
from ucamera_driver.sim import UCameraSim

JOINTS = ["pan", "tilt"]
LOG = logging.getLogger("test_device")


class Rig:
    """One controller around one adapter on the simulator's pty."""

    def __init__(self, sim: UCameraSim, **settings: object) -> None:
        self.sim = sim
        self.reports: list[object] = []
        # silence_timeout: 1.0 s was shorter than the in-process simulator's worst stall
        # under the parallel suite (a move failed with "no telemetry for 1.0 s" in a full
        # run); the link-drop test destroys the pty, which is seen at once anyway.
        self.settings = UCameraSettings(serial_port=sim.port_name, silence_timeout=3.0,
                                        request_timeout=1.0, **settings)
        self.config = ControllerConfig(
            joint_names=list(JOINTS),
            limits={"pan": JointLimits(-math.pi, math.pi, 3.0),
                    "tilt": JointLimits(-math.pi / 2, math.pi / 2, 3.0)},
            command_timeout=0.3, reconnect_period=0.1, move_timeout=30.0)
        self.device = UCameraDevice(
            self.settings, tolerance=lambda: self.config.goal_tolerance,
            on_report=lambda packet, stamp: self.reports.append(packet), log=LOG)
        self.controller = GimbalController(self.device, self.config, LOG)
        self.motion = Motion(self.controller)

    def start(self) -> Rig:
        self.controller.open()
        self.controller.activate()
        wait_for(lambda: self.device.functions.mode() == "angles", what="end of INIT")
        return self

    def close(self) -> None:
        self.controller.shutdown()

    def device_commanded(self) -> tuple[tuple[float, float], tuple[float, float], int]:
        model = self.sim.model
        with model.lock:
            return model.commanded_angles, model.commanded_rates, model.mode

    def device_angles(self) -> tuple[float, float]:
        model = self.sim.model
        with model.lock:
            return model.pan.position, model.tilt.position

    def at(self, pan: float, tilt: float, tol: float = 0.01) -> bool:
        positions = self.controller.positions()
        return (bool(positions) and abs(positions["pan"] - pan) < tol
                and abs(positions["tilt"] - tilt) < tol)

    def move(self, pan: float, tilt: float, speed: float = 0.0):
        speeds = [speed, speed] if speed else []
        targets = self.motion.start_move(JOINTS, [pan, tilt], speeds)
        return self.motion.wait_move(targets)


@pytest.fixture
def rig(sim: UCameraSim) -> Iterator[Rig]:
    setup = Rig(sim).start()
    yield setup
    setup.close()


def test_connect_reads_identity_and_streams(rig: Rig) -> None:
    info = rig.controller.device_info
    version = rig.sim.model.config.version
    assert info.model == "Airelectronics U-Camera (ir)"
    assert info.serial_number == version.serial_number
    assert info.hardware_id == f"ucamera-{version.serial_number}"
    assert rig.device.description() == f"serial://{rig.sim.port_name}?baudrate=115200"
    assert rig.device.streamed
    # each angles report is taken on the client's reader thread (streamed_samples)
    wait_for(lambda: rig.controller.latest is not None, what="a joint sample")
    assert set(rig.controller.latest.positions) == set(JOINTS)
    wait_for(lambda: any(isinstance(p, ZoomReport) for p in list(rig.reports)),
             what="reports reach the node's listener")


def test_rep103_conversion_both_ways(rig: Rig) -> None:
    outcome = rig.move(0.5, 0.3)
    assert outcome.success, outcome.message
    angles, _, mode = rig.device_commanded()
    assert mode == GimbalMode.ANGLES
    assert angles == pytest.approx((-0.5, 0.3), abs=1e-3)  # device pan is positive right
    assert rig.controller.positions()["pan"] == pytest.approx(0.5, abs=0.01)  # tolerance
    wait_for(lambda: rig.device_angles() == pytest.approx((-0.5, 0.3), abs=2e-3),
             what="the gimbal settled at device pan -0.5")
    wait_for(lambda: rig.at(0.5, 0.3, tol=2e-3), what="joint pan +0.5 reported")
    # rates: a positive (REP-103, left) pan jog is a negative device rate, and back
    rig.controller.command(["pan"], [], [0.3])
    wait_for(lambda: rig.device_commanded()[1] == pytest.approx((-0.3, 0.0), abs=1e-3),
             what="the device rate")
    wait_for(lambda: rig.controller.latest.velocities["pan"] > 0.25, what="positive velocity")
    rig.controller.stop()


def test_inverted_tilt_setting(sim: UCameraSim) -> None:
    setup = Rig(sim, invert_pan=False, invert_tilt=True).start()
    try:
        assert setup.move(0.2, 0.1).success
        assert setup.device_commanded()[0] == pytest.approx((0.2, -0.1), abs=1e-3)
        assert setup.at(0.2, 0.1)
    finally:
        setup.close()


def test_move_with_speed_ramps_the_setpoint_and_converges(rig: Rig) -> None:
    seen: list[float] = []
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            seen.append(rig.device_commanded()[0][0])
            done.wait(0.01)

    watcher = threading.Thread(target=watch)
    watcher.start()
    targets = rig.motion.start_move(JOINTS, [-0.6, 0.0], [0.6, 0.6])
    wait_for(lambda: is_moving(rig.controller.latest, "pan"), what="the moving bit")
    outcome = rig.motion.wait_move(targets)
    done.set()
    watcher.join()
    assert outcome.success, outcome.message
    assert rig.at(-0.6, 0.0)
    assert not is_moving(rig.controller.latest, "pan")
    # the device was told intermediate set-points (device pan = +0.6 at the end)
    assert any(0.1 < angle < 0.5 for angle in seen), seen
    wait_for(lambda: rig.device_commanded()[0][0] == pytest.approx(0.6, abs=1e-3),
             what="the last set-point is the target")


def test_moving_bit_follows_the_command_not_the_rates(rig: Rig) -> None:
    assert rig.move(0.2, 0.2).success
    wait_for(lambda: not is_moving(rig.controller.latest, "pan"), what="settled")
    sample = rig.controller.latest
    assert sample.moving == {"pan": False, "tilt": False}
    rig.controller.command(["tilt"], [], [0.4])
    wait_for(lambda: rig.controller.latest.moving.get("tilt") is True, what="jog moving")
    assert rig.controller.latest.moving["pan"] is False
    rig.controller.stop()
    wait_for(lambda: not any(rig.controller.latest.moving.values()), what="stopped")


def test_jog_is_stopped_by_the_watchdog(rig: Rig) -> None:
    rig.controller.command(["tilt"], [], [0.4])
    wait_for(lambda: rig.device_commanded()[2] == GimbalMode.RATES, what="rates mode")
    wait_for(lambda: rig.controller.latest.velocities["tilt"] > 0.3, what="the jog running")
    # no further joint_command: the dead-man watchdog zeroes the rate
    wait_for(lambda: rig.device_commanded()[1] == (0.0, 0.0), what="the watchdog stop")
    wait_for(lambda: abs(rig.controller.latest.velocities["tilt"]) < 1e-3, what="standstill")
    assert rig.controller.watchdog.jogging == []


def test_stop_holds_the_reported_angles(rig: Rig) -> None:
    targets = rig.motion.start_move(JOINTS, [-2.0, 0.0], [0.5, 0.5])
    outcomes = []
    waiter = threading.Thread(target=lambda: outcomes.append(rig.motion.wait_move(targets)))
    waiter.start()
    wait_for(lambda: abs(rig.controller.positions()["pan"]) > 0.2, what="the move running")
    assert "stopped" in rig.controller.stop()
    waiter.join()
    assert outcomes[0].state == "stopped"

    def holding() -> bool:  # the hold packet reaches the gimbal a moment after stop()
        model = rig.sim.model
        with model.lock:
            held = model.commanded_angles
            return (model.pan.velocity == 0.0 and model.tilt.velocity == 0.0
                    and (model.pan.position, model.tilt.position) == pytest.approx(held, abs=2e-3))

    wait_for(holding, what="holding the reported angles")
    assert abs(rig.device_commanded()[0][0]) < 1.5  # stopped short of the target (+2.0)


def test_refusals_send_nothing(rig: Rig) -> None:
    before = rig.device_commanded()
    with pytest.raises(InvalidRequest, match="outside"):
        rig.motion.start_move(["pan"], [4.0])
    with pytest.raises(InvalidRequest, match="velocity_max"):
        rig.controller.command(["pan"], [], [5.0])
    with pytest.raises(InvalidRequest, match="modes are"):
        rig.controller.call(lambda: rig.device.functions.set_mode("warp"))
    with pytest.raises(Unsupported, match="no fault-reset"):
        rig.controller.reset_faults()
    with pytest.raises(DeviceRefused, match="allow_nv_write"):
        rig.controller.call(rig.device.functions.save_configuration)
    with pytest.raises(InvalidRequest, match="zoom"):
        rig.controller.call(lambda: rig.device.functions.set_zoom(1.5))
    with pytest.raises(InvalidRequest, match="quaternion norm"):
        rig.controller.call(lambda: rig.device.functions.send_external_attitude(0.0, 0.0, 0.0, 2.0))
    assert rig.device_commanded() == before
    assert rig.sim.model.nv_saves == 0
    rig.controller.deactivate()
    assert "not active" in rig.controller.refusal()
    with pytest.raises(DeviceRefused, match="not active"):
        rig.controller.command(["pan"], [0.1], [])
    assert rig.device_commanded() == before


def test_home_goes_to_pilot(rig: Rig) -> None:
    assert rig.move(0.3, -0.3).success
    progress: list[str] = []
    message = rig.motion.home([], progress.append)
    assert "pilot" in message
    assert progress
    assert rig.device.functions.mode() == "pilot"
    # home returns on the device's own state; the controller's sample may be one behind
    wait_for(lambda: rig.at(0.0, 0.0), 5.0, "the controller's sample at pan 0 / tilt 0")


def test_set_mode_and_nv_save_with_opt_in(sim: UCameraSim) -> None:
    setup = Rig(sim, allow_nv_write=True).start()
    try:
        functions = setup.device.functions
        assert "mode stow active" in setup.controller.call(lambda: functions.set_mode("stow"))
        wait_for(lambda: setup.at(0.0, math.pi / 2), what="stow pose (tilt up)")
        answer = setup.controller.call(lambda: setup.device.functions.set_mode("gyro_autoalign"))
        assert "returns to angles by itself" in answer
        assert "saved" in setup.controller.call(setup.device.functions.save_configuration)
        wait_for(lambda: sim.model.nv_saves == 1, what="the NV write")
        wait_for(lambda: setup.device.functions.mode() == "angles", what="back in angles")
        assert setup.controller.connected  # the save pause is not a link loss
    finally:
        setup.close()


def test_external_feed_in_gimbal_frames(rig: Rig) -> None:
    rig.device.functions.send_external_velocity(east=1.0, north=2.0, up=0.5)
    rig.device.functions.send_external_attitude(0.0, 0.0, 0.0, 1.0)  # facing east, level
    rig.device.functions.send_external_body_rates(0.01, 0.02, 0.03)  # FLU
    wait_for(lambda: rig.sim.model.vehicle_rates is not None, what="vehicle rates")
    model = rig.sim.model
    assert model.external_velocity == pytest.approx((2.0, 1.0, -0.5))  # N, E, D
    assert model.vehicle_angles == pytest.approx((math.pi / 2, 0.0, 0.0), abs=1e-4)
    assert model.vehicle_rates == pytest.approx((-0.03, -0.02, 0.01), abs=1e-5)  # r, q, p


def test_link_drop_then_the_supervisor_reconnects(rig: Rig, caplog) -> None:
    rig.controller.set_command_timeout(0.0)  # no watchdog: the jog runs into the drop
    rig.controller.command(["pan"], [], [0.3])
    wait_for(lambda: rig.device_commanded()[1] == pytest.approx((-0.3, 0.0), abs=1e-3),
             what="jogging")
    rig.sim.drop_link(0.5)
    wait_for(lambda: not rig.controller.connected, what="the link loss")
    assert "U-Camera link down" in rig.controller.link_error
    with pytest.raises(DeviceRefused, match="not connected"):
        rig.controller.command(["pan"], [0.1], [])
    with pytest.raises(LinkError):
        rig.controller.stop()
    wait_for(lambda: rig.controller.connected, timeout=20.0, what="the reconnect")
    assert rig.controller.reconnects >= 1
    # the gimbal kept its last rates through the drop; after the reconnect it must not keep
    # jogging on them: either the adapter zeroed them (it found rates mode at connect), or
    # the gimbal had already left rates mode (then the stale rates do not move it). Which
    # one happens depends on whether a report showed the mode before the connect check.
    def jog_ended() -> bool:
        _, rates, mode = rig.device_commanded()
        return rates == (0.0, 0.0) or mode != GimbalMode.RATES

    wait_for(jog_ended, what="the stale jog to end")
    if rig.device_commanded()[1] != (0.0, 0.0):
        assert "rates mode at connect" not in caplog.text
    else:
        assert "rates mode at connect: rates set to zero" in caplog.text
    assert rig.device.client.stats.reconnects >= 1
    assert rig.move(-0.2, 0.1).success


# --- external-feed frame conversions (moved here from test_node_helpers.py; the
# quaternion <-> Euler round trip is in gimbal_driver_common/test/test_orientation.py) ---
@pytest.mark.parametrize(
    ("enu", "ned"),
    [
        ((0.0, 0.0, 0.0), (math.pi / 2, 0.0, 0.0)),  # facing east: heading 90
        ((0.0, 0.0, math.pi / 2), (0.0, 0.0, 0.0)),  # facing north: heading 0
        ((0.0, 0.0, -math.pi / 2), (math.pi, 0.0, 0.0)),  # facing south
        ((0.0, -0.2, math.pi / 2), (0.0, 0.2, 0.0)),  # FLU pitch -0.2 = nose up
        ((0.3, 0.0, math.pi / 2), (0.0, 0.0, 0.3)),  # right wing down in both
    ],
)
def test_enu_flu_to_ned_frd(enu, ned) -> None:
    yaw, pitch, roll = enu_flu_to_ned_frd(*enu)
    assert (abs(yaw), pitch, roll) == pytest.approx((abs(ned[0]), ned[1], ned[2]), abs=1e-9)


def test_an_unanswered_best_effort_read_never_keeps_the_gimbal_from_connecting(
        sim: UCameraSim, caplog) -> None:
    """The telemetry-rate read-back and the antenna position are best effort: the gimbal
    that never answers them connects, streams and moves; each is a WARN and a key."""
    sim.model.request_faults.mute("TelemetryRateRequest")
    sim.model.request_faults.mute("AntennaPositionRequest")
    setup = Rig(sim)
    with caplog.at_level(logging.WARNING):
        setup.start()
    try:
        assert setup.move(0.2, 0.1).success
        warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
        for name in ("TelemetryRateRequest", "AntennaPositionRequest"):
            assert any(name in line and "connecting without it" in line for line in warned)
        device = setup.device.capabilities.status.parts()[0]
        values = dict(device.values)
        assert device.level >= 1 and "TelemetryRateRequest" in device.message
        assert "unanswered.TelemetryRateRequest" in values
        assert "unanswered.AntennaPositionRequest" in values
    finally:
        setup.close()


def test_an_unanswered_required_request_names_itself(sim: UCameraSim) -> None:
    """The version answer is the handshake: without it nothing connects, and it is named."""
    sim.model.request_faults.mute("VersionRequest")
    setup = Rig(sim, connect_timeout=1.0)
    with pytest.raises(GimbalError, match="Request Gimbal Version") as raised:
        setup.controller.open()
    assert setup.controller.link_error == str(raised.value)
