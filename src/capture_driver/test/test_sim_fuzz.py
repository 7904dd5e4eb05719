"""The simulator never crashes on arbitrary input and answers valid requests sensibly."""

from __future__ import annotations

import time

from hypothesis import given, settings
from hypothesis import strategies as st

from capture_driver.protocol import BY_OPCODE, COMMANDS, Frame, ReplyCode, StreamDecoder
from capture_driver.sim import CaptureSession, PedestalModel
from gimbal_driver_testing import wait_for


def connected_session() -> CaptureSession:
    session = CaptureSession(PedestalModel(), greet=False)
    assert session.on_bytes(COMMANDS['COM_Connect'].encode()) == bytes([ReplyCode.ACK])
    return session


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200))
def test_garbage_never_crashes_the_simulator(data):
    session = connected_session()
    reply = session.on_bytes(data)
    for item in StreamDecoder().feed(reply):
        assert not hasattr(item, 'reason') or item.reason != 'checksum mismatch'


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(sorted(BY_OPCODE)), st.integers(0, 16), st.binary(max_size=48))
def test_any_table_opcode_with_any_payload_gets_one_answer(opcode, axis, data):
    session = connected_session()
    reply = session.on_bytes(Frame(0, axis, opcode, data).encode())
    items = StreamDecoder().feed(reply)
    assert len(items) == 1
    item = items[0]
    if isinstance(item, Frame):
        assert item.opcode == opcode and item.axis == axis
        assert BY_OPCODE[opcode].replies_with_data


def test_unknown_opcodes_are_invalid_commands():
    session = connected_session()
    for opcode in (0x0000, 0x0B05, 0x0FB6, 0xFFFF):  # incl. out-of-scope groups
        assert session.on_bytes(Frame(0, 1, opcode).encode()) == bytes([ReplyCode.INVALID_COMMAND])


def test_bad_checksum_gets_f6():
    session = connected_session()
    packet = bytearray(COMMANDS['MOT_GetLoadPosition'].encode(1))
    packet[-1] ^= 0x55
    assert session.on_bytes(bytes(packet)) == bytes([ReplyCode.WRONG_CHECKSUM])


def test_a_request_reads_the_axis_as_it_is_now():
    """The model advances to the wall clock before each request, as a controller's motion
    runs continuously: no physics thread runs here, and the move still shows in the reads."""
    session = connected_session()
    session.model.axes[1].move_to(90.0, speed=20.0)  # degrees, degrees per second
    getter = COMMANDS['MOT_GetLoadPosition']

    def position() -> float:
        (reply,) = StreamDecoder().feed(session.on_bytes(getter.encode(1)))
        return getter.decode_reply(reply)

    first = position()
    wait_for(lambda: position() > first + 0.05, 5.0, 'the move to show in a position read')


def test_request_counts_keep_every_request_past_the_trimmed_log():
    """A node polls 5,000 requests in about 20 s; the simulator keeps only the last few
    thousand frames, and counts every one (the ``count`` verb and ``state`` read them)."""
    session = connected_session()
    start = COMMANDS['LRF_StartMeasurement']
    getter = COMMANDS['MOT_GetLoadPosition'].encode(1)
    session.on_bytes(start.encode())
    for _ in range(6000):
        session.on_bytes(getter)
    session.on_bytes(start.encode())
    model = session.model
    assert len(model.requests) < 6002
    assert model.request_counts[start.opcode] == 2
    assert model.request_total == 6003  # with COM_Connect


def test_the_keepalive_expires_only_over_time_the_simulator_listened():
    """The host's silence is counted up to the reader's last run: a reader that stood still
    (a starved core) has not heard what the host sent; once it listens and still hears
    nothing for the allowed time, the axes go off as the controller's would."""
    session = connected_session()
    model = session.model
    model.keepalive_on, model.keepalive_timeout_ms, model.keepalive_count = True, 100, 3
    model.axes[1].axis_on = True
    model.last_command = time.monotonic() - 5.0
    model.last_listened = model.last_command - 1.0  # the reader stood still since
    model.advance()
    assert model.keepalive_on and model.axes[1].axis_on
    session.poll()  # the reader runs: 5 s of silence heard
    model.advance()
    assert not model.keepalive_on and not model.axes[1].axis_on
