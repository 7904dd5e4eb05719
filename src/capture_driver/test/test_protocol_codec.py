"""Codec properties: round trips, fuzzing, resynchronisation, table sanity, registers."""

from __future__ import annotations

import contextlib
import math
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from capture_driver.protocol import (
    BY_OPCODE,
    COMMANDS,
    REGISTERS,
    UNRESOLVED,
    DataType,
    Frame,
    FrameError,
    Garbage,
    PresetRecord,
    ProtocolError,
    ReplyByte,
    ReplyCode,
    Safety,
    StreamDecoder,
    UnknownCommand,
    command,
    ddmm_to_degrees,
    decode_frame,
    decode_value,
    degrees_to_ddmm,
    describe_reply,
    encode,
    encode_value,
)
from capture_driver.protocol.registers import CSR_ERROR_STRINGS

frames = st.builds(
    Frame,
    group=st.integers(0, 255),
    axis=st.integers(0, 255),
    opcode=st.integers(0, 0xFFFF),
    data=st.binary(max_size=60),
)


@settings(max_examples=200, deadline=None)
@given(frames)
def test_frame_round_trip(frame):
    assert decode_frame(frame.encode()) == frame
    assert StreamDecoder().feed(frame.encode()) == [frame]


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_decode_frame_raises_only_codec_errors(data):
    with contextlib.suppress(FrameError):
        decode_frame(data)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=40), max_size=8))
def test_stream_decoder_never_raises_and_accounts_every_byte(chunks):
    decoder = StreamDecoder()
    items = []
    for chunk in chunks:
        items += decoder.feed(chunk)
    items += decoder.flush_partial()
    while decoder.has_partial:
        items += decoder.flush_partial()
    total = 0
    for item in items:
        if isinstance(item, Frame):
            total += len(item.encode())
        elif isinstance(item, ReplyByte):
            total += 1
        else:
            assert isinstance(item, Garbage)
            total += len(item.data)
    assert total == sum(len(c) for c in chunks)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=50), frames, st.integers(1, 7))
def test_resynchronises_after_garbage(garbage, frame, split):
    # Garbage without a start byte in it, then a valid packet, fed in pieces.
    noise = bytes(b for b in garbage if b != 0x50)
    stream = noise + frame.encode()
    decoder = StreamDecoder()
    items = []
    for i in range(0, len(stream), split):
        items += decoder.feed(stream[i : i + split])
    assert frame in items


@settings(max_examples=200, deadline=None)
@given(frames, frames, frames, st.data())
def test_resynchronises_after_a_lost_byte(first, second, third, data):
    # The 8-bit checksum lets a truncated packet swallow the next one's start byte by
    # chance (1 in 256), so the promise is: found again within one packet.
    packet = first.encode()
    lost = data.draw(st.integers(0, len(packet) - 1))
    damaged = packet[:lost] + packet[lost + 1 :]
    decoder = StreamDecoder()
    items = decoder.feed(damaged + second.encode() + third.encode())
    while third not in items and decoder.has_partial:
        items += decoder.flush_partial()
    assert third in items


def test_corrupted_byte_reported_and_next_frame_found():
    good = command('MOT_Update').encode(1)
    bad = bytearray(command('MOT_GetMotorSpeed').encode(2))
    bad[5] ^= 0xFF
    decoder = StreamDecoder()
    items = decoder.feed(bytes(bad) + good + bytes([ReplyCode.ACK]))
    assert decoder.checksum_errors >= 1
    assert decode_frame(good) in items
    assert items[-1] == ReplyByte(ReplyCode.ACK)


def test_partial_frame_waits_then_flushes():
    decoder = StreamDecoder()
    packet = command('MOT_GetLoadPosition').encode(1)
    assert decoder.feed(packet[:5]) == []
    assert decoder.has_partial
    assert decoder.feed(packet[5:]) == [decode_frame(packet)]
    assert decoder.feed(b'\x50\x54\x08\x00') == []
    flushed = decoder.flush_partial()
    assert all(isinstance(i, Garbage) for i in flushed)


@settings(max_examples=200, deadline=None)
@given(st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_float32_round_trip(value):
    assert decode_value(DataType.F32, encode_value(DataType.F32, value)) == value


@settings(max_examples=100, deadline=None)
@given(
    st.text(alphabet=st.characters(min_codepoint=33, max_codepoint=126), max_size=16),
    st.lists(st.floats(-360, 360, width=32), min_size=6, max_size=6),
)
def test_preset_round_trip(name, angles):
    record = PresetRecord(name, tuple(angles))
    raw = encode_value(DataType.PRESET, record)
    assert len(raw) == 40
    assert decode_value(DataType.PRESET, raw) == record


@settings(max_examples=200, deadline=None)
@given(st.floats(-179.99, 179.99))
def test_ddmm_round_trip(value):
    assert ddmm_to_degrees(degrees_to_ddmm(value)) == pytest.approx(value, abs=1e-9)


def test_ddmm_example():
    assert ddmm_to_degrees(3453.49) == pytest.approx(34 + 53.49 / 60)
    assert ddmm_to_degrees(-3206.24) == pytest.approx(-(32 + 6.24 / 60))
    with pytest.raises(ProtocolError):
        ddmm_to_degrees(3475.0)


@pytest.mark.parametrize(
    ('dtype', 'value'),
    [
        (DataType.U8, 256), (DataType.U8, -1), (DataType.BOOL, 2), (DataType.U16, 70000),
        (DataType.F32, math.nan), (DataType.F32, 1e39), (DataType.F32, 'x'),
        (DataType.IPV4, '300.1.1.1'), (DataType.NONE, 5), (DataType.F32, None),
        (DataType.ASCII, 'é'), (DataType.LLA, (1, 2)), (DataType.PRESET, ('x' * 17, [0] * 6)),
    ],
)
def test_bad_values_raise_protocol_error(dtype, value):
    with pytest.raises(ProtocolError):
        encode_value(dtype, value)


@pytest.mark.parametrize('dtype', [d for d in DataType if d is not DataType.ASCII])
def test_wrong_reply_sizes_raise_protocol_error(dtype):
    with pytest.raises(ProtocolError):
        decode_value(dtype, b'\x00' * 41)


def test_axis_rules_are_enforced():
    with pytest.raises(ProtocolError, match='motor axis'):
        encode('MOT_GetLoadPosition')
    with pytest.raises(ProtocolError, match=r'outside 1\.\.3'):
        encode('MOT_GetLoadPosition', 4)
    with pytest.raises(ProtocolError, match='preset number'):
        encode('PRST_GoToPreset', 16)
    assert decode_frame(encode('SCN_StopScan')).axis == 0


def test_unknown_and_unresolved_commands_are_refused():
    with pytest.raises(UnknownCommand, match='not established'):
        command('GPS_GetAltitude')
    with pytest.raises(UnknownCommand, match='unknown command'):
        command('MOT_Fly')
    assert command('mot_update') is COMMANDS['MOT_Update']


def test_table_is_consistent():
    assert len(BY_OPCODE) == len(COMMANDS)
    for cmd in COMMANDS.values():
        assert re.fullmatch(r'[A-Z]{2,4}_[A-Za-z0-9]+', cmd.name)
        assert cmd.confidence in ('high', 'medium'), cmd.name
        assert cmd.evidence
        assert cmd.name not in UNRESOLVED
    # Anchors printed legibly in the spec.
    for name, opcode in [
        ('MOT_SendPosition', 0x0132), ('MOT_SetPositionAbsolute', 0x0139),
        ('MOT_MotionComplete', 0x0144), ('MOT_SetEmgStopAxes', 0x017D),
        ('SCN_SetStepHeight', 0x0404), ('SCN_StopScan', 0x0408), ('PRST_GetPreset', 0x0D00),
        ('PRST_SetPreset', 0x0D01), ('ERR_CaptureMotorErrorRegister', 0x0E0B),
        ('COM_IsConnected', 0x0704), ('IMU_GetYaw', 0x0604),
    ]:
        assert COMMANDS[name].opcode == opcode


def test_out_of_scope_groups_absent():
    for cmd in COMMANDS.values():
        assert not 0x0B00 <= cmd.opcode <= 0x0BFF  # weapon control unit group
        assert not 0x0FA0 <= cmd.opcode <= 0x0FCF  # dual-gimbal group (weapon-adjacent)


def test_safety_classes():
    assert COMMANDS['COM_Reboot'].safety is Safety.REBOOT
    assert COMMANDS['IP_SetControllerIP'].safety is Safety.NETWORK
    assert COMMANDS['MOT_SaveMotorSetting'].safety is Safety.NV_WRITE


def test_nack_descriptions_carry_advice():
    text = describe_reply(0xA6)
    assert 'Invalid command' in text and 'ERR_GetProtocolErrorString' in text
    assert 'power cycle' in describe_reply(0x16)
    assert describe_reply(0x42).startswith('unknown')


def test_registers_decode_named_flags():
    cmer = REGISTERS['CMER']
    active = {a.flag.name: a.flag.level for a in cmer.decode(0b1000_0000_1000_0011)}
    assert active == {'fault': 2, 'axis_on': 0, 'over_current': 2, 'can_bus_error': 2}
    srl = {a.flag.name for a in REGISTERS['SRL'].decode(0)}
    assert srl == {'axis_off'}
    for register in REGISTERS.values():
        assert COMMANDS[register.command].ret is DataType.U16 or register.name == 'SYS'
    for name in CSR_ERROR_STRINGS.values():
        assert COMMANDS[name].ret is DataType.ASCII


def test_generated_command_table_doc_is_current():
    from pathlib import Path

    from capture_driver.protocol.commands import markdown_table

    doc = Path(__file__).resolve().parent.parent / 'doc' / 'command_table.md'
    assert doc.read_text(encoding='utf-8').endswith(markdown_table()), (
        'regenerate doc/command_table.md from markdown_table()')
