"""Property tests: every data type round-trips; decoders raise only CodecError."""

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from canaero_turret_driver.protocol import (
    CanAerospaceMessage,
    CodecError,
    DataType,
    MessageCodeCounter,
    MessageCodeTracker,
    SequenceEvent,
    build_eed,
    decode_eed,
    decode_value,
    encode_value,
    join_double,
    split_double,
)
from canaero_turret_driver.protocol import nodeservice as ns
from canaero_turret_driver.protocol.identifiers import AxisStatus, decode_periphery

SETTINGS = settings(max_examples=200, deadline=None)

_INT_BOUNDS = {"b": (-128, 127), "B": (0, 255), "h": (-32768, 32767), "H": (0, 65535),
               "i": (-(2**31), 2**31 - 1), "I": (0, 2**32 - 1)}


def _value_strategy(data_type: DataType):
    from canaero_turret_driver.protocol.datatypes import codec_for

    codec = codec_for(data_type)
    letters = codec.struct_format.lstrip(">")
    if codec.kind == "none":
        return st.none()
    if codec.kind == "float":
        return st.floats(width=32, allow_nan=False)
    if codec.kind == "int":
        return st.integers(*_INT_BOUNDS[letters])
    if codec.kind == "ascii":
        return st.text(st.characters(max_codepoint=255), min_size=codec.size,
                       max_size=codec.size)
    if codec.kind == "error":
        return st.tuples(*(st.integers(*_INT_BOUNDS[letter]) for letter in letters))
    letter = letters[-1]
    return st.tuples(*(st.integers(*_INT_BOUNDS[letter]) for _ in range(codec.count)))


@pytest.mark.parametrize("data_type", list(DataType), ids=[t.name for t in DataType])
def test_every_data_type_round_trips(data_type):
    @SETTINGS
    @given(value=_value_strategy(data_type), can_id=st.integers(0, 2031),
           node_id=st.integers(0, 255), service=st.integers(0, 255),
           code=st.integers(0, 255), pad=st.booleans())
    def round_trip(value, can_id, node_id, service, code, pad):
        message = CanAerospaceMessage.build(can_id, node_id, data_type, value, service, code)
        frame = message.to_bytes(pad=pad)
        decoded = CanAerospaceMessage.from_frame(can_id, frame)
        assert decoded == message
        assert decoded.value == value
        assert encode_value(data_type, decode_value(data_type, message.payload)) == \
            message.payload

    round_trip()


@SETTINGS
@given(can_id=st.integers(0, 2047), data=st.binary(max_size=12))
def test_from_frame_raises_only_codec_error(can_id, data):
    try:
        message = CanAerospaceMessage.from_frame(can_id, data)
    except CodecError:
        return
    message.describe()  # decoding a parsed message must not raise either
    try:
        _ = message.value
    except CodecError:
        pytest.fail("a parsed message must decode")


@SETTINGS
@given(value=st.floats(allow_nan=False))
def test_double_halves_round_trip(value):
    high, low = split_double(value)
    assert join_double(high, low) == value
    message = CanAerospaceMessage.build(1500, 1, DataType.DOUBLEH, high)
    assert CanAerospaceMessage.from_frame(1500, message.to_bytes()).value == high


@pytest.mark.parametrize(("data_type", "value"), [
    (DataType.UCHAR, 256), (DataType.UCHAR, -1), (DataType.CHAR, 128), (DataType.SHORT2, (1,)),
    (DataType.USHORT2, (1, 70000)), (DataType.FLOAT, "x"), (DataType.FLOAT, 1e39),
    (DataType.LONG, 1.5), (DataType.ACHAR2, "abc"), (DataType.ACHAR, "\u20ac"),
    (DataType.NODATA, 3), (DataType.UCHAR, True), (200, b"12345"),
])
def test_bad_values_raise_codec_error(data_type, value):
    with pytest.raises(CodecError):
        encode_value(data_type, value)


def test_float_nan_and_infinity_are_ieee():
    assert encode_value(DataType.FLOAT, math.inf) == struct.pack(">f", math.inf)
    assert math.isnan(decode_value(DataType.FLOAT, encode_value(DataType.FLOAT, math.nan)))


@pytest.mark.parametrize(("can_id", "data", "reason"), [
    (1303, b"\x01\x02\x00", "needs 4"),
    (1303, b"\x01\x02\x00\x00\x41", "FLOAT (4 data bytes) but carries 1"),
    (1303, bytes(9), "max is 8"),
])
def test_malformed_frames_name_the_problem(can_id, data, reason):
    with pytest.raises(CodecError, match=reason.replace("(", r"\(").replace(")", r"\)")):
        CanAerospaceMessage.from_frame(can_id, data)


@pytest.mark.parametrize(("code", "name"), [
    (31, "DOUBLEL"), (32, "RESVD(32)"), (99, "RESVD(99)"), (100, "UDEF(100)"),
    (101, "UDEF(101)"), (102, "UDEF(102)"), (255, "UDEF(255)"),
])
def test_type_names_of_reserved_and_user_defined_codes(code, name):
    """RESVD 32-99, UDEF 100-255 (CANaerospace 1.7, libcanaerospace); the ICD's "102-255"
    would leave 100-101 unassigned."""
    from canaero_turret_driver.protocol.datatypes import type_name

    assert type_name(code) == name


def test_unknown_type_keeps_raw_payload():
    message = CanAerospaceMessage.from_frame(1303, bytes.fromhex("0164000001020304"))
    assert message.type_name == "UDEF(100)"
    assert message.value == bytes.fromhex("01020304")


def test_message_rejects_out_of_range_header_fields():
    with pytest.raises(CodecError):
        CanAerospaceMessage(2048, 1, 0)
    with pytest.raises(CodecError):
        CanAerospaceMessage(300, 256, 0)


# --- sequencing -----------------------------------------------------------------------

def test_sequence_in_order_with_rollover():
    tracker = MessageCodeTracker()
    events = [tracker.update("k", code)[0] for code in (254, 255, 0, 1)]
    assert events == [SequenceEvent.FIRST] + [SequenceEvent.IN_ORDER] * 3
    assert tracker.stats("k").anomalies == 0


def test_sequence_lost_repeated_late():
    tracker = MessageCodeTracker()
    tracker.update("k", 10)
    assert tracker.update("k", 13) == (SequenceEvent.LOST, 2)
    assert tracker.update("k", 13) == (SequenceEvent.REPEATED, 0)
    assert tracker.update("k", 12) == (SequenceEvent.LATE, 0)
    assert tracker.update("k", 14) == (SequenceEvent.IN_ORDER, 0)
    stats = tracker.stats("k")
    assert (stats.lost, stats.repeated, stats.late, stats.received) == (2, 1, 1, 5)


def test_sequence_lost_across_rollover_and_reset():
    tracker = MessageCodeTracker()
    tracker.update("k", 250)
    assert tracker.update("k", 4) == (SequenceEvent.LOST, 9)
    tracker.reset("k")
    assert tracker.update("k", 100)[0] is SequenceEvent.FIRST


@SETTINGS
@given(start=st.integers(0, 255), steps=st.lists(st.integers(1, 128), max_size=30))
def test_sequence_lost_count_matches_skipped(start, steps):
    tracker = MessageCodeTracker()
    tracker.update("k", start)
    code = start
    for step in steps:
        code = (code + step) % 256
        tracker.update("k", code)
    assert tracker.stats("k").lost == sum(step - 1 for step in steps)


def test_transmit_counter_rolls_over():
    counter = MessageCodeCounter()
    codes = [counter.next(1300) for _ in range(257)]
    assert codes[0] == 0 and codes[255] == 255 and codes[256] == 0
    assert counter.next(1301) == 0


# --- EED ------------------------------------------------------------------------------

@SETTINGS
@given(can_id=st.integers(0, 127), node=st.integers(0, 255), error=st.integers(0, 65535),
       operation=st.integers(0, 255), location=st.integers(0, 255))
def test_eed_round_trip(can_id, node, error, operation, location):
    message = build_eed(can_id, node, error, operation, location)
    frame = message.to_bytes()
    assert frame[1] == DataType.ERROR
    event = decode_eed(CanAerospaceMessage.from_frame(can_id, frame))
    assert (event.error_code, event.operation_id, event.location_id) == (error, operation,
                                                                          location)


def test_eed_layout_bytes():
    frame = build_eed(1, 1, 0x1234, 5, 6).to_bytes()
    assert frame == bytes.fromhex("0101000012340506")


def test_eed_outside_range_rejected():
    with pytest.raises(CodecError):
        decode_eed(CanAerospaceMessage.build(300, 1, DataType.ERROR, (1, 2, 3)))
    with pytest.raises(CodecError):
        decode_eed(CanAerospaceMessage.build(5, 1, DataType.FLOAT, 1.0))


# --- node services --------------------------------------------------------------------

def test_ids_request_and_response_layout():
    request = ns.ids_request(1)
    assert (request.can_id, request.to_bytes()) == (128, bytes.fromhex("01000000"))
    info = ns.IdentificationInfo(3, 7, 0, 0)
    response = ns.ids_response(1, info, message_code=request.message_code)
    assert response.to_bytes() == bytes.fromhex("0110000003070000")
    assert ns.is_response_to(request, response)
    assert ns.parse_ids_response(response) == info


def test_tis_request_layout_and_status_forms():
    request = ns.tis_request(1, 1303, 20, channel=100)
    assert request.can_id == 2000
    assert request.to_bytes() == bytes.fromhex("010C0500051700 14".replace(" ", ""))
    icd_form = ns.tis_response(1, -6, channel=100)
    assert icd_form.to_bytes() == bytes.fromhex("010005FA")
    assert ns.response_status(icd_form) == -6
    standard_form = CanAerospaceMessage.build(2001, 1, DataType.LONG, -6, 5, 0)
    assert ns.response_status(standard_form) == -6
    with pytest.raises(CodecError):
        ns.tis_request(1, 4000, 20)


def test_fps_and_nis_layouts():
    assert ns.fps_request(1, 0x5A).to_bytes() == bytes.fromhex("0100065A")
    assert ns.nis_request(1, 9).to_bytes() == bytes.fromhex("01000B09")
    with pytest.raises(CodecError):
        ns.nis_request(1, 200)
    with pytest.raises(CodecError):
        ns.nis_request(0, 5)
    assert ns.response_status(ns.fps_response(1, -3)) == -3


def test_transfer_helpers():
    data = bytes(range(10))
    chunks = ns.split_block(data)
    assert [len(c) for c in chunks] == [4, 4, 2]
    message = ns.chunk_message(128, 1, ns.ServiceCode.DDS, 3, chunks[2])
    assert message.data_type == DataType.UCHAR2 and message.message_code == 3
    assert ns.block_checksum(data) == 45
    start = ns.start_transfer_request(1, ns.ServiceCode.DUS, 7, 3)
    assert start.to_bytes() == bytes.fromhex("0115030300000007")
    with pytest.raises(CodecError):
        ns.split_block(bytes(1021))


@pytest.mark.parametrize("first", [0, 1])
def test_transfer_messages_are_numbered_from_the_chosen_first_number(first):
    data = bytes(range(10))
    messages = ns.transfer_messages(0x81, 1, ns.ServiceCode.DUS, data, first)
    assert [m.message_code for m in messages] == [first, first + 1, first + 2]
    assert [m.data_type for m in messages] == [DataType.UCHAR4, DataType.UCHAR4,
                                               DataType.UCHAR2]
    assert messages[0].to_bytes() == bytes((1, DataType.UCHAR4, 3, first, 0, 1, 2, 3))
    assert list(ns.data_numbers(255, first))[-1] == 254 + first  # still one byte
    assert ns.DEFAULT_FIRST_NUMBER == 0  # libcanaerospace's numbering


def test_transfer_numbering_other_than_0_or_1_is_refused():
    with pytest.raises(CodecError, match="0 or 1"):
        ns.data_numbers(3, 2)


def test_axis_status_and_periphery_bits():
    status = AxisStatus.decode(0b1000_1001)
    assert (status.target_name, status.mode_name, status.enabled) == ("reached",
                                                                       "auto_brake", True)
    assert AxisStatus.encode(1, 2, True) == 0b1000_1001
    bits = decode_periphery(0x181)
    assert bits["fan_enabled"] and bits["charging_enabled"]
    assert bits["case_temperature_sensor_fault"]
    assert not bits["oes_heater_enabled"]
    assert len(bits) == 7  # bits 5 and 6 are not decoded


def test_sequence_restart_is_detected_after_a_streak_of_late_codes():
    tracker = MessageCodeTracker()
    for code in (97, 98, 99, 100):
        tracker.update("k", code)
    assert tracker.update("k", 0)[0] is SequenceEvent.LATE
    assert tracker.update("k", 1)[0] is SequenceEvent.LATE
    assert tracker.update("k", 2)[0] is SequenceEvent.RESTARTED
    assert tracker.update("k", 3)[0] is SequenceEvent.IN_ORDER
    assert tracker.stats("k").restarts == 1


def test_constant_codes_become_unsequenced_then_tracked_again():
    tracker = MessageCodeTracker()
    events = [tracker.update("k", 0)[0] for _ in range(5)]
    assert events == [SequenceEvent.FIRST, SequenceEvent.REPEATED, SequenceEvent.REPEATED,
                      SequenceEvent.UNSEQUENCED, SequenceEvent.UNSEQUENCED]
    assert all(e.accepted for e in events[3:]) and not events[1].accepted
    assert tracker.stats("k").unsequenced
    assert tracker.update("k", 7)[0] is SequenceEvent.FIRST
    assert tracker.update("k", 8)[0] is SequenceEvent.IN_ORDER
    assert not tracker.stats("k").unsequenced
