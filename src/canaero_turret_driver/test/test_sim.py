"""Simulator pieces without a bus: slcan framing, axis physics, node services."""

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from canaero_turret_driver.protocol import CanAerospaceMessage, DataType
from canaero_turret_driver.protocol import nodeservice as ns
from canaero_turret_driver.sim import (
    AxisModel,
    SlcanSession,
    TurretSimulator,
    encode_slcan,
    make_control,
)


class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_slcan_session_commands_and_frames():
    sim = TurretSimulator()
    session = SlcanSession(sim)
    assert session.on_bytes(b"S6\r") == b"\r"
    assert session.on_bytes(b"V\r") == b"V1013\r"
    request = ns.ids_request(1)
    record = encode_slcan(can.Message(arbitration_id=request.can_id, is_extended_id=False,
                                      data=request.to_bytes()))
    assert record == b"t0804" + b"01000000" + b"\r"
    assert session.on_bytes(record) == b"z\r"  # channel closed: accepted, not delivered
    assert session.on_bytes(b"O\r") == b"\r"
    reply = session.on_bytes(record[:5]) + session.on_bytes(record[5:])
    assert reply.startswith(b"z\rt0818011000000207")
    assert session.on_bytes(b"tZZZ1\r") == b"\a"
    assert session.on_bytes(b"q\r") == b"\a"
    assert session.on_bytes(b"t12398\r") == b"\a"  # DLC 9
    assert session.on_bytes(b"x" * 100) == b"\a"  # over-long line dropped
    assert session.rejected_records == 4
    assert session.poll()  # broadcasts flow once open


def test_axis_physics_limits_and_profile():
    pitch = AxisModel("pitch", max_velocity=40.0, acceleration=180.0, min_position=-30.0,
                      max_position=60.0)
    pitch.jog(40.0)
    for _ in range(400):
        pitch.step(0.01)
    assert pitch.position == 60.0 and pitch.velocity == 0.0 and pitch.mode == "idle"
    pitch.move_to(10.0)
    peak = 0.0
    for _ in range(400):
        pitch.step(0.01)
        peak = max(peak, abs(pitch.velocity))
    assert pitch.position == pytest.approx(10.0) and peak <= 40.0


def test_yaw_wraps_and_counts_revolutions():
    yaw = AxisModel("yaw", max_velocity=60.0, acceleration=180.0)
    yaw.jog(60.0)
    for _ in range(400):
        yaw.step(0.01)
    assert -180.0 <= yaw.reported_position < 180.0
    assert yaw.revolutions == 1


def test_services_answer_on_request_channel():
    clock = FakeClock()
    sim = TurretSimulator(clock=clock)
    request = ns.tis_request(2, 1409, 250, channel=101)
    frame = can.Message(arbitration_id=request.can_id, is_extended_id=False,
                        data=request.to_bytes())
    (reply,) = sim.handle(frame)
    assert reply.arbitration_id == 2003
    response = CanAerospaceMessage.from_frame(reply.arbitration_id, reply.data)
    assert ns.response_status(response) == 0
    assert sim.state()["intervals_ms"]["cover_state"] == 250
    # The turret does not transmit the cover's id: out of range.
    request = ns.tis_request(1, 1409, 250)
    (reply,) = sim.handle(can.Message(arbitration_id=128, is_extended_id=False,
                                      data=request.to_bytes()))
    assert ns.response_status(CanAerospaceMessage.from_frame(129, reply.data)) == -6
    # Broadcast IDS: every node answers.
    request = ns.ids_request(0)
    replies = sim.handle(can.Message(arbitration_id=128, is_extended_id=False,
                                     data=request.to_bytes()))
    assert sorted(r.data[0] for r in replies) == [1, 2, 5, 6, 7]


def test_wrong_data_type_command_gives_eed():
    sim = TurretSimulator()
    bad = CanAerospaceMessage.build(1300, 100, DataType.LONG, 20)
    replies = sim.handle(can.Message(arbitration_id=1300, is_extended_id=False,
                                     data=bad.to_bytes()))
    frames = [f for f in replies if f.arbitration_id == 1]
    assert frames and frames[0].data[1] == DataType.ERROR
    assert sim.handle(can.Message(arbitration_id=1300, is_extended_id=False,
                                  data=b"\x64")) == []
    assert sim.malformed_received == 1


def test_control_commands_report_errors():
    clock = FakeClock()
    sim = TurretSimulator(clock=clock)
    control = make_control(sim)  # on a python-can bus: no byte link
    assert control.execute("node_silence nobody").startswith("error")
    assert control.execute("lose not_a_key").startswith("error")
    assert control.execute("drop").startswith("error drop: canaero_turret_sim has no byte")
    assert control.execute("nack on").startswith("error nack: not applicable")
    assert control.execute("fault drive pitch") == "ok"
    assert sim.state()["axes"]["pitch"]["fault"]
    assert control.execute("fault case_sensor") == "ok"
    assert any(f.arbitration_id == 1 for f in sim.poll())  # the drive fault's EED
    assert control.execute("silence on") == "ok"
    assert sim.poll() == []  # every node silent
    assert control.execute("clear") == "ok"
    assert not sim.state()["axes"]["pitch"]["fault"]
    clock.now += 1.0
    assert sim.poll()  # broadcasting again
    assert '"axes"' in control.execute("state")


@settings(max_examples=200, deadline=None)
@given(chunks=st.lists(st.binary(max_size=40), max_size=8))
def test_slcan_session_survives_any_bytes(chunks):
    session = SlcanSession(TurretSimulator())
    session.on_bytes(b"O\r")
    for chunk in chunks:
        out = session.on_bytes(chunk)
        for record in out.split(b"\r")[:-1]:
            record = record.lstrip(b"\a")
            assert record == b"" or record[:1] in b"tzVNF", record
