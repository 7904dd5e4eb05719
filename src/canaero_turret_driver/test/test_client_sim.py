"""Client against the simulator on a python-can virtual bus (one process)."""

import math

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from canaero_turret_driver.client import (
    ClientConfig,
    CommandError,
    LinkError,
    NotAllowedError,
    ServiceError,
    TurretClient,
)
from canaero_turret_driver.protocol import ActuatorMode, AxisStatus, CanAerospaceMessage
from canaero_turret_driver.protocol.identifiers import DEFAULT_ZOOM_POSITION_ID
from canaero_turret_driver.readings import si
from canaero_turret_driver.sim import BusSimRunner, EedCode, SimConfig, TurretSimulator
from gimbal_driver_testing import wait_for


def _latest(client, key, field):
    """``field(sample)`` of the latest sample of ``key``, None before the first one."""
    sample = client.latest(key)
    return None if sample is None else field(sample)


def _si(client, key):
    return _latest(client, key, si)


def _enabled(client, key):
    return _latest(client, key, lambda sample: AxisStatus.decode(sample.value).enabled)


def _value(client, key):
    return _latest(client, key, lambda sample: sample.value)


def _target(client, key):
    return _latest(client, key, lambda sample: AxisStatus.decode(sample.value).target_name)


def test_identify_and_data_arrive(client):
    info = client.services.identify()
    assert (info.hardware_revision, info.software_revision) == (2, 7)
    assert info.identifier_distribution == 0 and info.header_type == 0
    for key in ("yaw_position", "pitch_position", "cover_state", "latitude", "global_yaw",
                "zoom_position", "periphery_status"):
        assert wait_for(lambda k=key: client.latest(k) is not None), key
    assert not client.node_silent()
    assert si(client.latest("latitude")) == pytest.approx(48.1372)
    assert si(client.latest("altitude_msl")) == pytest.approx(519.0)
    assert client.services.identify(node_id=6).hardware_revision == 2  # base GNSS node answers too


def test_absolute_move_reaches_target(client, simulator):
    wait_for(lambda: client.latest("yaw_position") is not None)
    client.move_to("yaw", math.degrees(0.5))
    client.move_to("pitch", math.degrees(-0.2))
    assert wait_for(lambda: abs((_si(client, "yaw_position") or 9) - 0.5) < 1e-3)
    assert wait_for(lambda: abs((_si(client, "pitch_position") or 9) + 0.2) < 1e-3)
    assert wait_for(lambda: _target(client, "yaw_status") == "reached")


def test_yaw_takes_shortest_path_across_180(client, simulator):
    client.move_to("yaw", 170.0)
    assert wait_for(lambda: abs(simulator.state()["axes"]["yaw"]["position"] - 170) < 0.01)
    client.move_to("yaw", -170.0)
    assert wait_for(lambda: abs(simulator.state()["axes"]["yaw"]["position"] + 170) < 0.01)
    assert simulator.state()["axes"]["yaw"]["revolutions"] == 1
    assert wait_for(lambda: _value(client, "yaw_revolutions") == 1)


def test_jog_then_stop(client, simulator):
    client.jog("pitch", 10.0)
    assert wait_for(lambda: (_si(client, "pitch_velocity") or 0) > math.radians(9))
    assert wait_for(lambda: _target(client, "pitch_status") == "jog")
    client.stop(["pitch"])
    assert wait_for(lambda: simulator.state()["axes"]["pitch"]["velocity"] == 0.0)
    assert wait_for(lambda: _si(client, "pitch_velocity") == 0.0)


def test_relative_move(client, simulator):
    client.move_by("yaw", 30.0)
    assert wait_for(lambda: abs(simulator.state()["axes"]["yaw"]["position"] - 30) < 1e-3)
    client.move_by("yaw", -10.0)
    assert wait_for(lambda: abs(simulator.state()["axes"]["yaw"]["position"] - 20) < 1e-3)


def test_free_run_rejects_moves_with_eed(client, simulator):
    client.set_actuator_mode("yaw", ActuatorMode.FREE_RUN)
    assert wait_for(lambda: _value(client, "yaw_actuator_mode_state") == 0)
    client.move_to("yaw", math.degrees(1.0))
    assert wait_for(lambda: any(e.error_code == EedCode.COMMAND_REJECTED
                                for e in client.events))
    event = client.events[-1]
    assert (event.node_id, event.location_id) == (1, 1)
    assert wait_for(lambda: _enabled(client, "yaw_status") is False)
    client.set_actuator_mode("yaw", ActuatorMode.AUTO_BRAKE)
    client.move_to("yaw", math.degrees(0.3))
    assert wait_for(lambda: abs(simulator.state()["axes"]["yaw"]["position"]
                                - math.degrees(0.3)) < 1e-3)


def test_remember_and_restore_position(client, simulator):
    client.move_to("yaw", math.degrees(0.4))
    assert wait_for(lambda: abs(simulator.state()["axes"]["yaw"]["position"]
                                - math.degrees(0.4)) < 1e-3)
    client.remember_position()
    assert wait_for(lambda: simulator.state()["saved_position"] is not None)
    client.move_to("yaw", math.degrees(-0.4))
    assert wait_for(lambda: abs(simulator.state()["axes"]["yaw"]["position"]
                                + math.degrees(0.4)) < 1e-3)
    client.restore_position()
    assert wait_for(lambda: abs(simulator.state()["axes"]["yaw"]["position"]
                                - math.degrees(0.4)) < 1e-3)


def test_periphery_commands(client):
    client.set_fan(True)
    client.set_oes_heater(True)
    client.set_charging(True)
    client.set_cover(True)
    assert wait_for(lambda: _value(client, "fan_state") == 1)
    assert wait_for(lambda: ((_value(client, "periphery_status") or 0) & 0x87) == 0x87)
    assert wait_for(lambda: _value(client, "charging_state") == 1)
    assert wait_for(lambda: _value(client, "cover_state") == 2)  # middle first
    assert wait_for(lambda: _value(client, "cover_state") == 1)


def test_transmission_interval_service(client, simulator):
    client.services.set_transmission_interval("case_temperature", 50)
    assert simulator.state()["intervals_ms"]["case_temperature"] == 50
    client.services.set_transmission_interval("cover_state", 0)
    assert simulator.state()["intervals_ms"]["cover_state"] == 0
    assert not client.is_stale("cover_state")  # disabled on purpose: not stale
    with pytest.raises(ServiceError, match="out of range"):
        client.services.set_transmission_interval("yaw_position", 5)
    with pytest.raises(CommandError):
        client.services.set_transmission_interval("yaw_position_setpoint", 50)


def test_zoom_position_is_a_long_count_on_id_1342(client):
    assert DEFAULT_ZOOM_POSITION_ID == 1342
    assert wait_for(lambda: client.latest("zoom_position") is not None)
    sample = client.latest("zoom_position")
    assert sample.value == 2500 and isinstance(sample.value, int)
    assert client.data_type_of("zoom_position").name == "LONG"


def test_accepted_intervals_drive_staleness(client, simulator):
    # the simulator, like the turret, sends positions every 100 ms until asked otherwise
    assert simulator.state()["intervals_ms"]["yaw_position"] == 100
    refused = client.services.request_intervals({"yaw_position": 20, "pitch_position": 20,
                                        "case_temperature": 2000})
    assert refused == {} and client.intervals.refused == {}
    assert simulator.state()["intervals_ms"]["yaw_position"] == 20
    assert client.intervals.interval_of("yaw_position") == pytest.approx(0.02)
    assert client.intervals.accepted_interval_ms("case_temperature") == 2000
    assert client.stale_timeout_for("case_temperature") == pytest.approx(6.0)
    assert client.stale_timeout_for("yaw_position") == client.config.stale_timeout


@pytest.fixture
def refusing_client(channel_name):
    sim = TurretSimulator(SimConfig(refuse_tis=True))
    bus = can.Bus(interface="virtual", channel=channel_name)
    runner = BusSimRunner(sim, bus).start()
    turret = TurretClient(ClientConfig(interface="virtual", channel=channel_name,
                                       service_timeout=0.5, stale_timeout=0.1))
    turret.open()
    yield turret, sim
    turret.close()
    runner.stop()
    bus.shutdown()


def test_refused_intervals_fall_back_to_the_observed_rate(refusing_client):
    client, sim = refusing_client
    refused = client.services.request_intervals({"yaw_position": 20, "pitch_position": 20})
    assert set(refused) == {"yaw_position", "pitch_position"}
    assert "out of range" in refused["yaw_position"]
    assert sim.state()["intervals_ms"]["yaw_position"] == 100
    assert client.intervals.accepted_interval_ms("yaw_position") is None
    # learned from the frames: about 100 ms, so staleness allows 3 x that
    assert wait_for(lambda: client.intervals.interval_of("yaw_position") is not None
                    and client.intervals.interval_of("yaw_position") > 0.05)
    assert client.stale_timeout_for("yaw_position") > 0.15
    assert wait_for(lambda: not client.is_stale("yaw_position"))


def test_refused_and_timed_out_intervals_are_told_apart(refusing_client):
    """A TIS answered with a negative status is refused; one never answered timed out,
    and the log/diagnostics text says which (the turret did not refuse it)."""
    client, sim = refusing_client
    client.services.request_intervals({"yaw_position": 20})
    assert set(client.intervals.refused) == {"yaw_position"} and not client.intervals.timed_out
    assert client.intervals.failures() == "the turret refused TIS for yaw_position"
    sim.request_faults.mute("TIS")
    failed = client.services.request_intervals({"yaw_position": 20, "pitch_position": 20})
    assert set(failed) == {"yaw_position", "pitch_position"}
    assert not client.intervals.refused
    assert "no TIS response" in client.intervals.timed_out["pitch_position"]
    assert client.intervals.failures() == ("TIS for pitch_position, yaw_position timed out "
                                           "(no answer)")
    assert "refused" not in client.intervals.failures()


def test_node_id_and_flash_services_need_opt_in(client, simulator):
    before = simulator.state()["commands_received"]
    with pytest.raises(NotAllowedError):
        client.services.set_node_id(9)
    with pytest.raises(NotAllowedError):
        client.services.store_configuration(0x5A)
    assert simulator.state()["node_ids"]["turret"] == 1
    assert simulator.state()["commands_received"] == before


def test_node_id_and_flash_services_when_enabled(simulator, channel_name):
    config = ClientConfig(interface="virtual", channel=channel_name, service_timeout=0.5,
                          allow_node_id_change=True, allow_flash_programming=True)
    turret = TurretClient(config)
    turret.open()
    try:
        with pytest.raises(ServiceError, match="invalid security code"):
            turret.services.store_configuration(0x11)
        turret.services.store_configuration(0x5A)
        assert simulator.state()["stored_configuration"]
        with pytest.raises(CommandError):
            turret.services.set_node_id(200)
        turret.services.set_node_id(9)
        assert simulator.state()["node_ids"]["turret"] == 9
        assert turret.config.turret_node_id == 9
        assert turret.services.identify().software_revision == 7
        assert wait_for(lambda: turret.latest("yaw_position") is not None
                        and turret.latest("yaw_position").node_id == 9)
    finally:
        turret.close()


def test_invalid_commands_send_nothing(client, simulator):
    wait_for(lambda: client.latest("yaw_position") is not None)
    before = simulator.state()["commands_received"]
    # (the -180..180 degree set-point range is the adapter's: test_device.py)
    for bad in (lambda: client.move_to("yaw", math.nan),
                lambda: client.jog("pitch", math.inf), lambda: client.move_to("roll", 0.1),
                lambda: client.set_actuator_mode("yaw", 7),
                lambda: client.command("yaw_position", 1.0)):
        with pytest.raises(CommandError):
            bad()
    assert simulator.state()["commands_received"] == before


def test_silence_goes_stale_and_recovers(client, simulator):
    client.config.node_timeout = 0.3
    client.config.stale_timeout = 0.3
    assert wait_for(lambda: not client.node_silent())
    simulator.set_silent("turret")
    assert wait_for(lambda: client.node_silent() and client.is_stale("yaw_position"))
    assert not client.node_silent(2)  # cover keeps talking
    with pytest.raises(ServiceError, match="no IDS response"):
        client.services.identify()
    simulator.set_silent("turret", 0)
    assert wait_for(lambda: not client.node_silent() and not client.is_stale("yaw_position"))
    assert client.services.identify().hardware_revision == 2


def test_lost_repeated_frames_and_malformed_frames_are_counted(client, simulator):
    assert wait_for(lambda: client.latest("yaw_position") is not None)
    events = []
    client.on_sequence = lambda key, event, missed: events.append((key, event.value, missed))
    simulator.lose_frames("yaw_position", 3)
    simulator.repeat_frames("pitch_position", 2)
    simulator.send_malformed(3)
    assert wait_for(lambda: client.sequences.stats((1, 1303)).lost >= 3)
    assert wait_for(lambda: client.sequences.stats((1, 1313)).repeated >= 2)
    assert wait_for(lambda: client.counters.malformed >= 3)
    assert client.counters.type_mismatch >= 1
    assert ("yaw_position", "lost", 3) in events
    # Values still flow after the faults.
    code = client.latest("yaw_position").message_code
    assert wait_for(lambda: client.latest("yaw_position").message_code != code)


def test_injected_eed_and_axis_fault(client, simulator):
    simulator.emit_eed(0x1234, 5, 6)
    assert wait_for(lambda: any(e.error_code == 0x1234 for e in client.events))
    simulator.set_axis_fault("pitch")
    assert wait_for(lambda: any(e.error_code == EedCode.DRIVE_FAULT for e in client.events))
    assert wait_for(lambda: _enabled(client, "pitch_status") is False)
    client.set_actuator_mode("pitch", ActuatorMode.AUTO_BRAKE)  # re-initialises the drive
    assert wait_for(lambda: _enabled(client, "pitch_status") is True)


def test_unknown_and_out_of_scope_ids_are_ignored(client, spy_bus):
    assert wait_for(lambda: client.latest("yaw_position") is not None)
    before = client.counters.unknown
    for can_id in (1401, 1402, 1406, 1410, 1411, 1412, 1416, 1417, 1418, 1999):
        frame = CanAerospaceMessage.build(can_id, 1, 10, 1).to_bytes()
        spy_bus.send(can.Message(arbitration_id=can_id, is_extended_id=False, data=frame))
    assert wait_for(lambda: client.counters.unknown >= before + 10)
    assert all(key not in client.snapshot() for key in ("fuse", "bolt", "trigger"))
    # A data id from the wrong node is not taken as the turret's.
    frame = CanAerospaceMessage.build(1303, 42, 2, 99.0).to_bytes()
    spy_bus.send(can.Message(arbitration_id=1303, is_extended_id=False, data=frame))
    assert wait_for(lambda: client.counters.foreign_node >= 1)


def test_commands_use_master_node_id_and_rolling_codes(client, spy_bus):
    client.move_to("yaw", math.degrees(0.1))
    client.move_to("yaw", math.degrees(0.2))
    seen = []
    for _ in range(200):
        frame = spy_bus.recv(timeout=0.5)
        if frame is None:
            break
        if frame.arbitration_id == 1300:
            seen.append(bytes(frame.data))
        if len(seen) == 2:
            break
    assert [f[0] for f in seen] == [100, 100]
    assert [f[3] for f in seen] == [0, 1]
    assert len(seen[0]) == 8  # FLOAT: 4 header + 4 data bytes


def test_interface_errors_drop_the_bus_and_open_reopens_it(simulator, channel_name, flaky_bus):
    """The client has no reconnect loop: an interface error drops the bus (and ends the
    receive thread); close() + open() reopens it. test_device.py has the supervisor
    doing that by itself."""
    script = ["raise", "busoff"]
    links = []
    config = ClientConfig(interface="virtual", channel=channel_name, service_timeout=0.5)
    turret = TurretClient(config, bus_factory=lambda cfg: flaky_bus(cfg.channel, script))
    turret.on_link = lambda up, why: links.append((up, why))
    turret.open()
    try:
        for reason in ("adapter unplugged", "bus-off"):
            assert wait_for(lambda r=reason: any(r in why for up, why in links if not up)), links
            assert not turret.connected
            with pytest.raises(LinkError, match="not open"):
                turret.move_to("yaw", 0.1)
            turret.close()
            turret.open()
        assert turret.counters.reconnects == 2
        assert turret.counters.bus_errors >= 1
        assert wait_for(lambda: turret.latest("yaw_position") is not None)
        assert turret.services.identify().software_revision == 7
        assert turret.connected
    finally:
        turret.close()


def test_send_without_interface_is_a_clear_error():
    turret = TurretClient(ClientConfig(interface="virtual", channel="unused"))
    with pytest.raises(LinkError, match="not open"):
        turret.move_to("yaw", 0.1)


def test_open_failure_is_a_link_error():
    def broken(config):
        raise can.CanInitializationError("no such device can9")

    turret = TurretClient(ClientConfig(channel="can9"), bus_factory=broken)
    with pytest.raises(LinkError, match="can9"):
        turret.open()
    turret.close()


def test_staleness_follows_each_identifiers_own_rate():
    turret = TurretClient(ClientConfig(stale_timeout=0.5))
    assert turret.stale_timeout_for("case_temperature") == 0.5
    for gap in (1.0, 1.0, 1.0):
        turret.intervals.learn("case_temperature", gap)
    assert turret.stale_timeout_for("case_temperature") == pytest.approx(3.0)
    turret.intervals.learn("case_temperature", 60.0)  # an outage does not inflate it
    assert turret.stale_timeout_for("case_temperature") == pytest.approx(3.0)
    turret.intervals.learn("yaw_position", 0.02)
    assert turret.stale_timeout_for("yaw_position") == 0.5


def test_data_download_and_upload(client, simulator):
    text = client.services.upload(16, 26)
    assert text == b"CANAERO-TURRET-SIM hw2 sw7"
    block = bytes(range(1, 42))  # 41 bytes: 11 data messages, the last with one byte
    assert client.services.download(1, block) == sum(block)
    assert bytes(simulator.memories[1].data[:41]) == block
    assert client.services.upload(1, 41) == block
    with pytest.raises(ServiceError, match="INVALID"):
        client.services.download(16, b"read-only")
    with pytest.raises(ServiceError, match="ABORT"):
        client.services.upload(99, 4)
    with pytest.raises(CommandError):
        client.services.download(1, b"")
    with pytest.raises(CommandError):
        client.services.upload(1, 2000)
    assert client.services.identify().software_revision == 7  # the service channel is free again


@pytest.fixture
def numbered_rig(channel_name, request):
    """(client, simulator) counting DDS/DUS data messages from client_first / sim_first."""
    client_first, sim_first = request.param
    sim = TurretSimulator(SimConfig(transfer_first_number=sim_first))
    bus = can.Bus(interface="virtual", channel=channel_name)
    runner = BusSimRunner(sim, bus).start()
    spy = can.Bus(interface="virtual", channel=channel_name)
    turret = TurretClient(ClientConfig(interface="virtual", channel=channel_name,
                                       service_timeout=0.5,
                                       transfer_first_number=client_first))
    turret.open()
    yield turret, sim, spy
    turret.close()
    spy.shutdown()
    runner.stop()
    bus.shutdown()


def _transfer_numbers(spy, can_id):
    numbers = []
    while (frame := spy.recv(timeout=0)) is not None:  # what is queued so far
        if frame.arbitration_id == can_id and frame.data[1] in (10, 19, 27, 16):  # UCHAR..4
            numbers.append(frame.data[3])
    return numbers


@pytest.mark.parametrize("numbered_rig", [(0, 0), (1, 1)], indirect=True,
                         ids=["from_0", "from_1"])
def test_transfers_in_either_numbering(numbered_rig):
    client, _, spy = numbered_rig
    first = client.config.transfer_first_number
    block = bytes(range(1, 10))  # 9 bytes: 3 data messages
    assert client.services.download(1, block) == sum(block)
    assert _transfer_numbers(spy, 128) == [first, first + 1, first + 2]
    assert client.services.upload(1, 9) == block
    assert _transfer_numbers(spy, 129) == [first, first + 1, first + 2]


@pytest.mark.parametrize("numbered_rig", [(1, 0), (0, 1)], indirect=True,
                         ids=["client_1_node_0", "client_0_node_1"])
def test_transfer_numbering_mismatch_is_named(numbered_rig, channel_name):
    client, sim, _ = numbered_rig
    with pytest.raises(ServiceError, match="transfer_first_number"):
        client.services.download(1, b"abcdefgh")
    assert bytes(sim.memories[1].data[:8]) == bytes(8)  # nothing was written
    with pytest.raises(ServiceError, match="transfer_first_number"):
        client.services.upload(16, 8)


def test_device_restart_of_message_codes_is_followed(client, simulator):
    from canaero_turret_driver.protocol import MessageCodeCounter

    assert wait_for(lambda: client.latest("yaw_position") is not None
                    and client.latest("yaw_position").message_code > 10)
    simulator._codes = MessageCodeCounter()  # as after a power cycle: codes from 0 again
    client.move_to("yaw", math.degrees(0.2))
    assert wait_for(lambda: abs((_si(client, "yaw_position") or 9) - 0.2) < 1e-3)
    assert client.sequences.stats((1, 1303)).restarts == 1


@settings(max_examples=200, deadline=None)
@given(can_id=st.integers(0, 0x7FF), data=st.binary(max_size=8),
       extended=st.booleans(), error=st.booleans())
def test_dispatch_never_raises_on_any_frame(can_id, data, extended, error):
    turret = TurretClient(ClientConfig())
    frame = can.Message(arbitration_id=can_id, data=data, is_extended_id=extended,
                        is_error_frame=error)
    turret._dispatch(frame)
    assert turret.counters.frames == 1
