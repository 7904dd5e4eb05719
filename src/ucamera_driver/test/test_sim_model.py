"""Simulator device model on a manual clock (no pty, deterministic)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time

import pytest
import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gimbal_driver_common.sim_control import ControlClient, control_state, read_ready_line
from gimbal_driver_testing import wait_for
from ucamera_driver.protocol import (
    FrameParser,
    GimbalMode,
    GimbalType,
    IrPaletteReport,
    SaveConfiguration,
    SetAngles,
    SetMode,
    SetRates,
    TelemetryRateRequest,
    VersionRequest,
    encode_frame,
)
from ucamera_driver.protocol.packets import ALL_PACKETS
from ucamera_driver.sim import Faults, UCameraModel, UCameraSession, UCameraSim, build_arg_parser


class ManualClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def run(model: UCameraModel, clock: ManualClock, seconds: float, dt: float = 0.005) -> None:
    for _ in range(round(seconds / dt)):
        clock.now += dt
        model.step()


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


@pytest.fixture
def model(clock: ManualClock, make_config) -> UCameraModel:
    device = UCameraModel(make_config(max_rate=math.radians(60.0),
                                      acceleration=math.radians(240.0)), clock=clock)
    run(device, clock, 0.3)
    assert device.mode == GimbalMode.ANGLES  # INIT ends by itself (4.1)
    return device


def test_init_ignores_mode_commands(clock: ManualClock, make_config) -> None:
    device = UCameraModel(make_config(init_time=1.0), clock=clock)
    device.handle(SetMode(GimbalMode.RATES))
    assert device.mode == GimbalMode.INIT


def test_slew_respects_speed_and_acceleration(model, clock) -> None:
    model.handle(SetAngles(math.radians(90), 0.0))
    top_speed = 0.0
    previous = 0.0
    for _ in range(600):
        clock.now += 0.005
        model.step()
        top_speed = max(top_speed, abs(model.pan.velocity))
        # one step of slack for the final snap onto the target
        assert abs(model.pan.velocity - previous) <= 2 * math.radians(240.0) * 0.005
        previous = model.pan.velocity
    assert top_speed == pytest.approx(math.radians(60.0))
    assert model.pan.position == pytest.approx(math.radians(90))


def test_commands_of_another_mode_have_no_effect(model, clock) -> None:
    model.handle(SetRates(0.5, 0.0))  # ANGLES mode: ignored (5.5.3.3)
    run(model, clock, 0.5)
    assert model.pan.position == 0.0
    model.handle(SetMode(GimbalMode.RATES))
    model.handle(SetAngles(1.0, 0.0))  # RATES mode: ignored (5.5.3.5)
    run(model, clock, 0.5)
    assert model.pan.position == 0.0


def test_rates_stop_at_the_mechanical_limit(model, clock) -> None:
    model.handle(SetMode(GimbalMode.RATES))
    model.handle(SetRates(0.0, math.radians(60)))
    run(model, clock, 3.0)
    assert model.tilt.position == pytest.approx(math.pi / 2)
    assert model.tilt.velocity == 0.0


def test_save_configuration_pause(model, clock) -> None:
    model.handle(SaveConfiguration())
    assert model.silent()
    assert model.handle(VersionRequest()) == []  # deaf while writing
    assert model.ignored["VersionRequest"] == 1
    clock.now += 0.7
    assert not model.silent()
    assert model.handle(TelemetryRateRequest())


def test_periodic_set_depends_on_gimbal_type(clock, make_config) -> None:
    ir = UCameraModel(make_config(), clock=clock).periodic_reports()
    day = UCameraModel(make_config(gimbal_type=GimbalType.DAYLIGHT), clock=clock)
    assert any(isinstance(p, IrPaletteReport) for p in ir)
    assert not any(isinstance(p, IrPaletteReport) for p in day.periodic_reports())


def test_unknown_mode_number_is_ignored(model) -> None:
    model.handle(SetMode.from_payload(b"\x09\x00"))
    assert model.mode == GimbalMode.ANGLES
    assert model.ignored["SetMode"] == 1


def test_corruption_fault_breaks_the_checksum() -> None:
    faults = Faults()
    faults.corrupt_next = 1
    parser = FrameParser()
    assert parser.feed(faults.apply(SetAngles(0.1, 0.1).encode())) == []
    assert parser.stats.checksum_errors + parser.stats.length_errors == 1
    assert len(parser.feed(faults.apply(SetAngles(0.1, 0.1).encode()))) == 1


def test_text_commands(make_config) -> None:
    sim = UCameraSim(make_config())
    assert sim.command("corrupt 3") == "ok"
    assert sim.faults.corrupt_next == 3
    assert sim.command("drop_rate 0.5") == "ok"
    assert sim.faults.drop_probability == 0.5
    assert sim.command("fire").startswith("error fire: unknown verb")
    assert "bad arguments" in sim.command("noise_rate lots")
    assert json.loads(sim.command("state")[3:])["mode"] == "init"
    assert sim.command("nack on").startswith("error nack: not applicable")
    assert sim.command("fault 1").startswith("error fault: not applicable")
    assert sim.command("clear") == "ok"
    assert sim.faults.corrupt_next == 0 and sim.faults.drop_probability == 0.0


def test_sim_process_ready_line_and_shared_verbs_over_the_pty() -> None:
    """The ucamera_sim process: its JSON ready line names the pty; drop, silence and
    garbage from its TCP console act on the serial link a client reads."""
    proc = subprocess.Popen([sys.executable, "-m", "ucamera_driver.sim", "--init-time", "0.1"],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
    try:
        ready = read_ready_line(proc.stdout, "ucamera_sim")
        with ControlClient(ready["control_port"]) as control, \
                serial.Serial(ready["pty"], 115200, timeout=0.2) as port:
            def received(seconds: float) -> bytes:
                data, deadline = b"", time.monotonic() + seconds
                while time.monotonic() < deadline:
                    data += port.read(4096)
                return data

            assert len(received(0.3)) > 0  # telemetry streams
            marker = "c0ffee00deadbeef5aa5"
            assert control.command(f"garbage hex {marker}") == "ok 10 bytes"
            wait_for(lambda: bytes.fromhex(marker) in received(0.2), 10, "the garbage bytes")
            assert control.command("silence on") == "ok"
            received(0.2)  # what was already under way
            assert received(0.5) == b""
            assert control.command("silence off") == "ok"
            wait_for(lambda: received(0.2), 10, "telemetry again")
            assert control.command("drop 0.5") == "ok"
            with pytest.raises(serial.SerialException):
                for _ in range(50):
                    port.read(4096)
        wait_for(lambda: os.path.exists(ready["pty"]), 10, "the pty to come back")
        assert control_state(ready["control_port"])["axes"]["pan"]["position"] == 0.0
    finally:
        proc.terminate()
        proc.wait(10)


def test_cli_defaults() -> None:
    args = build_arg_parser().parse_args([])
    assert args.telemetry_rate == 50
    assert args.gimbal_type == "ir"


@settings(max_examples=200, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.lists(st.sampled_from(ALL_PACKETS).flatmap(lambda cls: st.tuples(
    st.just(cls),
    st.binary(min_size=cls.payload_length(), max_size=cls.payload_length())
    | st.binary(max_size=30))), max_size=12))
def test_session_survives_arbitrary_payloads(make_config, data) -> None:
    """Any frame a client might send (right ids, random payloads) never breaks the sim."""
    sim = UCameraSim(make_config())
    session = UCameraSession(sim)
    wire = b"".join(encode_frame(cls.CATEGORY, cls.PACKET_ID, payload) for cls, payload in data)
    session.on_bytes(wire)
    session.poll()
    assert 1 <= sim.model.telemetry_rate <= 200
    assert sim.model.periodic_reports()
