"""Hypothesis round-trip and fuzz tests of the kOS codec."""

import contextlib
import struct

from hypothesis import given, settings
from hypothesis import strategies as st

from kessler_kos_driver.protocol import (
    ACTIONS,
    NOTIFICATIONS,
    AuxInputStatus,
    AxisBlock,
    BumpPositionSpeedAcceleration,
    DeviceGuid,
    DeviceInfo,
    DevicePassword,
    ErrorStatus,
    FrameParser,
    GetDeviceGuid,
    GetDeviceInfo,
    GetLedStatus,
    GetMotorInfo,
    GetNetworkInfo,
    GetSoftwareId,
    GetTrajectoryData,
    LedStatus,
    MarkBeginPosition,
    MarkEndPosition,
    MessageType,
    MotorCalibrated,
    MotorInfo,
    MotorInfoEntry,
    MotorPosition,
    MotorStatus,
    MotorStatusEntry,
    NetworkInfo,
    PlaybackBlock,
    PlaybackStatus,
    ProtocolError,
    RapidToFirstKeyFrame,
    RawBlock,
    ResetAxis,
    ResetDevice,
    SegmentBlock,
    SetPositionSpeedAcceleration,
    SetupPlayback,
    SoftwareId,
    StartPlayback,
    StopPlayback,
    TakePicture,
    TimeLapseBlock,
    TrajectoryData,
    UnknownMessage,
    UnsupportedMessage,
    UserPassword,
    decode,
)

f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
pos_f32 = st.floats(min_value=0, max_value=1e6, width=32)
u8 = st.integers(0, 255)
u32 = st.integers(0, 2**32 - 1)
addr = st.integers(1, 10)
text = st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=40)

motor_info_entry = st.builds(MotorInfoEntry, addr, f32, f32, f32, f32, f32, f32, st.booleans())
motor_status_entry = st.builds(MotorStatusEntry, u8, st.booleans(), u8, f32, f32, f32)
playback_block = st.builds(
    PlaybackBlock, u8, f32, f32, u8, u8, st.sampled_from([0, 1]), f32, st.booleans(), f32, f32,
    st.booleans(), u8, f32, st.booleans(), st.booleans(), f32,
) | st.builds(PlaybackBlock, u8, f32, f32, u8, u8, st.just(2), u32.map(float))
blocks = st.lists(
    playback_block
    | st.builds(TimeLapseBlock, f32, f32, u32, u8, u32, u32)
    | st.builds(AxisBlock, u8, u8)
    | st.builds(SegmentBlock, u8, u8, f32, f32, f32, f32, f32, f32, f32, f32)
    | st.builds(RawBlock, st.sampled_from([0, 3, 4, 7, 200]), st.binary(max_size=20)),
    max_size=12,
)

messages = st.one_of(
    st.builds(GetNetworkInfo, st.booleans()),
    st.sampled_from([GetLedStatus(), GetMotorInfo(), GetDeviceInfo(), GetTrajectoryData(),
                     GetDeviceGuid(), GetSoftwareId()]),
    st.builds(NetworkInfo, st.booleans(), st.binary(min_size=6, max_size=6), u32, u32, u32, u8,
              u8, st.sampled_from([MessageType.SET, MessageType.RESPONSE])),
    st.builds(LedStatus, u8, u8, st.sampled_from([MessageType.SET, MessageType.RESPONSE])),
    st.builds(MotorInfo, st.lists(motor_info_entry, max_size=4), st.booleans()),
    st.builds(DeviceInfo, u8, u8, u8, u8, u8, u8, u8, u8, u8, u8, text, u8, f32, f32, u32),
    st.builds(UserPassword, text),
    st.builds(DevicePassword, text),
    st.builds(DeviceGuid, st.binary(max_size=32)),
    st.builds(SoftwareId, u8, st.sampled_from([MessageType.SET, MessageType.RESPONSE])),
    st.builds(TrajectoryData, blocks, st.sampled_from([MessageType.SET, MessageType.RESPONSE])),
    st.sampled_from([ResetDevice(), StopPlayback(), RapidToFirstKeyFrame()]),
    st.builds(ResetAxis, st.integers(0, 10)),
    st.builds(MarkBeginPosition, addr),
    st.builds(MarkEndPosition, addr),
    st.builds(StartPlayback, u8, f32),
    st.builds(SetupPlayback, u8, f32, st.booleans()),
    st.builds(TakePicture, st.integers(0, 10), pos_f32),
    st.builds(SetPositionSpeedAcceleration, addr, f32, pos_f32, pos_f32),
    st.builds(BumpPositionSpeedAcceleration, addr, f32, pos_f32, pos_f32),
    st.builds(MotorStatus, st.lists(motor_status_entry, max_size=4)),
    st.builds(PlaybackStatus, u8, f32, f32, st.dictionaries(addr, f32, max_size=5)),
    st.builds(ErrorStatus, u8, u8),
    st.builds(MotorPosition, u8, f32),
    st.builds(MotorCalibrated, u8, f32, f32),
    st.builds(AuxInputStatus, u8),
    st.builds(UnsupportedMessage, st.binary(max_size=30)),
)


@settings(max_examples=200, deadline=None)
@given(messages)
def test_round_trip(message):
    frame = message.encode()
    assert struct.unpack('>H', frame[1:3])[0] == len(frame)
    assert decode(frame) == message


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=80))
def test_decode_arbitrary_bytes_raises_only_protocol_errors(data):
    with contextlib.suppress(ProtocolError):
        decode(data)


@settings(max_examples=200, deadline=None)
@given(st.integers(0x00, 0xFF), st.sampled_from([0, 1, 2, 0x82]), st.binary(max_size=60))
def test_decode_any_well_framed_payload(message_id, message_type, payload):
    frame = bytes([4]) + struct.pack('>HHB', 6 + len(payload), message_id, message_type) + payload
    try:
        decoded = decode(frame)
    except ProtocolError:
        return
    if isinstance(decoded, UnknownMessage):
        assert decoded.encode() == frame


@settings(max_examples=200, deadline=None)
@given(st.lists(messages, min_size=1, max_size=5),
       st.lists(st.binary(max_size=12).map(lambda b: b.replace(b'\x04', b'')), min_size=5,
                max_size=5),
       st.integers(1, 17))
def test_parser_resynchronises_after_garbage(batch, garbage, chunk):
    frames = [m.encode() for m in batch]
    stream = b''.join(g + f for g, f in zip(garbage, frames, strict=False))
    parser = FrameParser()
    out = []
    for i in range(0, len(stream), chunk):
        out += parser.feed(stream[i:i + chunk])
    assert out == frames
    assert parser.discarded_bytes == sum(len(g) for g in garbage[:len(frames)])


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_parser_never_raises_and_accounts_for_every_byte(data):
    parser = FrameParser()
    frames = parser.feed(data)
    assert sum(map(len, frames)) + parser.discarded_bytes + parser.pending == len(data)
    for frame in frames:
        with contextlib.suppress(ProtocolError):
            decode(frame)


def test_action_and_notification_tables_cover_the_document():
    assert sorted(ACTIONS) == [1, 2, 3, 4, 5, 6, 7, 9, 15, 28, 40]
    assert sorted(NOTIFICATIONS) == [1, 2, 3, 7, 17, 21, 255]


def test_unknown_action_and_notification_ids_decode_as_unknown():
    for message_id, sub in ((0x80, 0x30), (0x81, 0x40)):
        frame = bytes([4, 0, 8, 0, message_id, 0, sub, 1])
        decoded = decode(frame)
        assert isinstance(decoded, UnknownMessage) and decoded.sub_id == sub
