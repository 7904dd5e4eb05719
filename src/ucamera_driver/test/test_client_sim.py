"""Client against the simulator over a real pseudo-terminal (pyserial)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest

from gimbal_driver_common.errors import DeviceTimeout, LinkError
from gimbal_driver_testing import wait_for
from ucamera_driver.client import UCameraClient, UCameraError
from ucamera_driver.protocol import (
    AntennaPositionReport,
    GimbalMode,
    GimbalType,
    GpsFeed,
    RangeError,
    VersionRequest,
    encode_frame,
)
from ucamera_driver.sim import UCameraSim


def make_client(sim: UCameraSim, **kwargs) -> UCameraClient:
    # shorter than the driver's 1.5 s so the silence tests end sooner, and long enough
    # that a loaded test machine's scheduling gaps (0.4 s was seen) are not silences
    kwargs.setdefault("silence_timeout", 1.0)
    return UCameraClient(sim.port_name, **kwargs)


@pytest.fixture
def client(sim: UCameraSim) -> Iterator[UCameraClient]:
    session = make_client(sim)
    session.start(timeout=3.0)
    wait_for(lambda: session.state().mode == GimbalMode.ANGLES, what="end of INIT")
    yield session
    session.stop()


def close(a: float | None, b: float, tol: float = 2e-3) -> bool:
    return a is not None and abs(a - b) < tol


def test_identity_and_telemetry(sim: UCameraSim, client: UCameraClient) -> None:
    assert client.version == sim.model.config.version
    state = wait_for(lambda: client.state().zoom is not None and client.state(), what="reports")
    assert state.gimbal_type == GimbalType.IR
    assert state.ir_palette == 0
    assert state.latitude == pytest.approx(sim.model.config.latitude)
    wait_for(lambda: client.telemetry_rate_achieved() > 0, what="a measured rate")
    assert client.connected


def test_angles_mode_slews_to_target(sim: UCameraSim, client: UCameraClient) -> None:
    client.set_angles(math.radians(30), math.radians(-20))
    wait_for(lambda: close(client.state().pan, math.radians(30))
             and close(client.state().tilt, math.radians(-20)), what="target reached")
    assert sim.model.mode == GimbalMode.ANGLES


def test_rates_mode_and_hold(sim: UCameraSim, client: UCameraClient) -> None:
    client.set_rates(math.radians(20), 0.0)
    wait_for(lambda: client.state().mode == GimbalMode.RATES, what="rates mode")
    wait_for(lambda: close(client.state().pan_rate, math.radians(20), 1e-3), what="pan rate")
    client.hold()
    wait_for(lambda: client.state().pan_rate == 0.0, what="stopped")
    assert sim.model.commanded_rates == (0.0, 0.0)


def test_refresh_resends_mode_and_command(sim: UCameraSim, client: UCameraClient) -> None:
    client.set_angles(0.1, 0.1)
    before = sim.model.received.get("SetAngles", 0)
    wait_for(lambda: sim.model.received.get("SetAngles", 0) >= before + 3, what="refresh")
    assert sim.model.received["SetMode"] >= 3


@pytest.mark.parametrize(
    ("mode", "pose"),
    [(GimbalMode.STOW, (0.0, math.pi / 2)), (GimbalMode.PILOT, (0.0, 0.0))],
)
def test_stow_and_pilot_poses(sim, client, mode, pose) -> None:
    client.set_angles(0.5, -0.5)
    client.set_mode(mode)
    wait_for(lambda: client.state().mode == mode, what=f"{mode.name} reported")
    wait_for(lambda: close(client.state().pan, pose[0]) and close(client.state().tilt, pose[1]),
             what=f"{mode.name} pose")


@pytest.mark.parametrize(
    "mode", [GimbalMode.FFC_CALIBRATION, GimbalMode.GYRO_AUTOALIGN, GimbalMode.FULL_AUTOALIGN]
)
def test_self_ending_modes_return_to_angles(sim, client, mode) -> None:
    client.set_angles(math.radians(10), math.radians(10))
    wait_for(lambda: close(client.state().pan, math.radians(10)), what="start pose")
    client.set_mode(mode)
    wait_for(lambda: client.state().mode == mode, what=f"{mode.name} entered")
    # the refresh must not abort it: the client waits for the device to finish
    wait_for(lambda: client.state().mode == GimbalMode.ANGLES, what="back in angles")
    assert client.pending_automatic_mode is None
    assert client.desired_mode == GimbalMode.ANGLES
    wait_for(lambda: close(client.state().pan, math.radians(10)), what="back to commanded angles")


def test_ffc_on_daylight_gimbal_is_reported(make_config) -> None:
    with UCameraSim(make_config(gimbal_type=GimbalType.DAYLIGHT)) as sim:
        client = make_client(sim, one_shot_timeout=0.3)
        client.start()
        try:
            wait_for(lambda: client.state().mode == GimbalMode.ANGLES, what="angles")
            client.set_mode(GimbalMode.FFC_CALIBRATION)
            wait_for(lambda: "did not enter ffc_calibration" in client.mode_error,
                     what="an error naming the mode")
            assert client.state().mode == GimbalMode.ANGLES
            assert client.state().ir_palette is None  # no IR report on a daylight gimbal
        finally:
            client.stop()


def test_requests_frequency_and_antenna(sim: UCameraSim, client: UCameraClient) -> None:
    assert client.commands.set_telemetry_rate(20) == 20
    assert client.request_telemetry_rate() == 20
    client.commands.set_antenna_position(0.12, -0.034, 0.5)
    assert client.request_antenna_position() == pytest.approx((0.12, -0.034, 0.5))


def test_zoom_and_palette(sim: UCameraSim, client: UCameraClient) -> None:
    client.commands.set_zoom(0.25)
    client.commands.set_ir_palette(4)
    wait_for(lambda: close(client.state().zoom, 0.25, 1e-3), what="zoom")
    wait_for(lambda: client.state().ir_palette == 4, what="palette")


def test_external_gps_feed_reaches_system_position(sim, client) -> None:
    client.commands.configure_gps_feed(GpsFeed.EXTERNAL)
    client.commands.send_gps(10.5, -20.25, 123.0, 1.0, 2.0, -0.5)
    client.commands.send_vehicle_angles(0.1, 0.2, -0.3)
    client.commands.send_vehicle_rates(0.01, 0.02, 0.03)
    wait_for(lambda: close(client.state().latitude, 10.5, 1e-6), what="external position")
    assert client.state().altitude == pytest.approx(123.0)
    assert sim.model.vehicle_angles == pytest.approx((0.1, 0.2, -0.3), abs=1e-6)
    assert sim.model.vehicle_rates == pytest.approx((0.01, 0.02, 0.03), abs=1e-6)
    assert sim.model.external_velocity == pytest.approx((1.0, 2.0, -0.5))


def test_out_of_range_command_sends_nothing(sim: UCameraSim, client: UCameraClient) -> None:
    sent = client.stats.commands_sent
    with pytest.raises(RangeError, match="pan"):
        client.set_angles(10.0, 0.0)
    with pytest.raises(RangeError, match="zoom"):
        client.commands.set_zoom(2.0)
    with pytest.raises(RangeError, match="not a U-Camera mode"):
        client.set_mode(12)
    assert client.stats.commands_sent == sent


def test_noise_and_corruption_are_survived(sim: UCameraSim, client: UCameraClient) -> None:
    for _ in range(20):
        sim.inject_noise(200)
    sim.corrupt(next_frames=10)
    wait_for(lambda: client.stats.checksum_errors >= 1, what="checksum errors counted")
    assert client.stats.discarded_bytes > 0
    client.set_angles(-0.3, 0.2)
    wait_for(lambda: close(client.state().pan, -0.3) and close(client.state().tilt, 0.2),
             what="commands still work")
    assert client.connected


def restart(client: UCameraClient) -> None:
    """What the controller's supervisor does after a link loss: close, then open again."""
    client.stop()

    def started() -> bool:
        try:
            client.start(timeout=0.5)
        except UCameraError:
            return False
        return True

    wait_for(started, what="the link to open again")


def test_silence_then_recovery(sim: UCameraSim, client: UCameraClient) -> None:
    sim.set_silent(True)
    wait_for(lambda: not client.connected, what="silence detected")
    wait_for(lambda: client.link_down, what="the link given up")
    assert client.stats.silences >= 1
    assert "no telemetry" in client.last_error
    with pytest.raises(UCameraError):  # the link is down: no reopening by the client
        client.request_telemetry_rate(timeout=0.1)
    sim.set_silent(False)
    restart(client)
    assert client.connected
    assert client.request_telemetry_rate() == 50
    assert client.stats.reconnects == 1


def test_packets_not_understood_are_named_not_silence(sim: UCameraSim,
                                                     client: UCameraClient) -> None:
    """The gimbal keeps sending well-framed packets, but none the driver knows (another
    firmware): the link is given up, and the reason says so (not a bare "no telemetry")."""
    sim.set_silent(True)  # the model's telemetry stops; injected bytes still go out
    unknown = encode_frame(0x03, 0x7E, b"\x01\x02")  # a packet id the manual does not list

    def dropped() -> bool:
        sim.server.inject(unknown)
        return not client.connected

    wait_for(dropped, what="the link given up")
    assert "no telemetry the driver understands" in client.last_error, client.last_error
    assert client.stats.unknown_packets > 0
    sim.set_silent(False)


def test_link_drop_is_reported_and_start_reopens(sim: UCameraSim, client: UCameraClient) -> None:
    client.set_angles(0.2, 0.0)
    sim.drop_link(offline_for=0.3)
    wait_for(lambda: not client.connected, what="link loss noticed")
    wait_for(lambda: client.link_down, what="the link given up")
    with pytest.raises(LinkError):
        client.set_angles(-0.2, 0.1)
    restart(client)
    assert client.stats.reconnects >= 1
    client.set_angles(-0.2, 0.1)
    wait_for(lambda: close(client.state().pan, -0.2), what="commands after reconnect")


def test_errors_are_the_core_hierarchy(sim: UCameraSim, client: UCameraClient) -> None:
    with pytest.raises(DeviceTimeout):
        client.request(VersionRequest(), AntennaPositionReport, timeout=0.05, attempts=1)
    client.stop()
    with pytest.raises(LinkError, match=r"link .* is down"):
        client.commands.set_zoom(0.5)


def test_save_configuration_pause_is_not_silence(sim: UCameraSim, client: UCameraClient) -> None:
    client.commands.set_telemetry_rate(25)
    client.commands.save_configuration()
    wait_for(lambda: sim.model.nv_saves == 1, what="NV write")
    wait_for(lambda: sim.model.silent(), what="device quiet", timeout=1.0)
    wait_for(lambda: not sim.model.silent(), what="device back")
    wait_for(lambda: client.request_telemetry_rate() == 25, what="answers again")
    assert client.stats.silences == 0
    assert sim.model.nv["telemetry_rate"] == 25


def test_start_fails_clearly_without_device(tmp_path) -> None:
    missing = UCameraClient(str(tmp_path / "no-such-tty"))
    with pytest.raises(LinkError, match=r"did not answer.*no-such-tty"):
        missing.start(timeout=0.5)
    assert not missing.running


def test_start_fails_on_silent_device(sim: UCameraSim) -> None:
    sim.set_silent(True)
    client = make_client(sim)
    with pytest.raises(UCameraError, match="did not answer"):
        client.start(timeout=0.6)
    assert not client.running
