"""The chunked slcan reader against the simulator's slcan adapter on a pseudo-terminal."""

import time

import can
import pytest

from canaero_turret_driver.protocol import CanAerospaceMessage, DataType
from canaero_turret_driver.sim import SimConfig, SlcanSession, TurretSimulator
from canaero_turret_driver.slcan import ChunkedSlcanBus, open_bus
from gimbal_driver_common.sim_server import PtySimServer


@pytest.fixture
def adapter(tmp_path):
    simulator = TurretSimulator(SimConfig())
    server = PtySimServer(lambda: SlcanSession(simulator), link_path=str(tmp_path / "tty"))
    server.start()
    yield simulator, server
    server.stop()


@pytest.fixture
def bus(adapter):
    _, server = adapter
    slcan = open_bus("slcan", server.port_name, sleep_after_open=0)
    yield slcan
    slcan.shutdown()


def _frames(bus, count, timeout=10.0):
    frames = []
    deadline = time.monotonic() + timeout
    while len(frames) < count and time.monotonic() < deadline:
        frame = bus.recv(timeout=0.5)
        if frame is not None:
            frames.append(frame)
    return frames


def test_open_bus_picks_the_chunked_reader_for_slcan(bus):
    assert isinstance(bus, ChunkedSlcanBus)
    virtual = open_bus("virtual", "chunked-slcan-test")
    try:
        assert not isinstance(virtual, ChunkedSlcanBus)
    finally:
        virtual.shutdown()


def test_receives_every_broadcast_intact(bus):
    frames = _frames(bus, 60)
    assert len(frames) == 60
    for frame in frames:
        message = CanAerospaceMessage.from_frame(frame.arbitration_id, frame.data)
        assert message.node_id in (1, 2, 5, 6, 7)
    assert 1303 in {frame.arbitration_id for frame in frames}  # yaw position


def test_send_reaches_the_device(adapter, bus):
    simulator, _ = adapter
    command = CanAerospaceMessage.build(1300, 100, DataType.FLOAT, 20.0, 0, 0)
    bus.send(can.Message(arbitration_id=1300, is_extended_id=False, data=command.to_bytes()))
    deadline = time.monotonic() + 10.0
    while simulator.state()["axes"]["yaw"]["mode"] != "position":
        assert time.monotonic() < deadline, "the position set-point never arrived"
        time.sleep(0.02)


def test_records_split_across_reads_and_garbage_resynchronise(adapter, bus):
    _, server = adapter
    bus.flush()
    record = b"t5178" + CanAerospaceMessage.build(1303, 1, DataType.FLOAT, 1.5, 0, 9).to_bytes(
        pad=True).hex().upper().encode()
    # garbage without a terminator longer than any record, then one record
    server.inject(b"\xff" * 80 + b"\r" + record + b"\r")
    found = []
    deadline = time.monotonic() + 10.0
    while not found and time.monotonic() < deadline:
        try:
            frame = bus.recv(timeout=0.5)
        except (ValueError, can.CanError):
            continue  # the garbled record is reported, as python-can's slcan does
        if frame is not None and frame.arbitration_id == 1303:
            message = CanAerospaceMessage.from_frame(1303, frame.data)
            if message.message_code == 9:
                found.append(message)
    assert found and found[0].value == pytest.approx(1.5)


def test_split_keeps_a_partial_record_for_the_next_chunk(bus):
    bus._split(b"t51780100")
    assert not bus._records
    bus._split(b"0000\rt5")
    assert list(bus._records) == ["t517801000000\r"]
    bus._records.clear()
    bus._split(b"x" * 70)
    assert bus._records and bus._records[-1].endswith("\a")  # resynchronised


def test_a_send_that_went_out_is_not_a_write_timeout(adapter, bus, monkeypatch):
    """The node sends with a 0.2 s timeout. A sending thread descheduled for longer used to
    get pyserial's SerialTimeoutException after every byte was written (the link was then
    dropped); the record arrives and the send succeeds."""
    import gimbal_driver_common.transport as transport

    simulator, _ = adapter
    write = transport.os.write

    def descheduled(fd, data):
        time.sleep(0.3)
        return write(fd, data)

    monkeypatch.setattr(transport.os, "write", descheduled)
    command = CanAerospaceMessage.build(1300, 100, DataType.FLOAT, 20.0, 0, 0)
    bus.send(can.Message(arbitration_id=1300, is_extended_id=False, data=command.to_bytes()),
             timeout=0.2)
    deadline = time.monotonic() + 10.0
    while simulator.state()["axes"]["yaw"]["mode"] != "position":
        assert time.monotonic() < deadline, "the position set-point never arrived"
        time.sleep(0.02)
