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
        assert re.fullmatch(r'[A-Z]{2,6}_[A-Za-z0-9]+', cmd.name)
        assert cmd.confidence in ('high', 'medium', 'low'), cmd.name
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


# Dual-gimbal weapon and CapSnap entries (rev 2.17.0/2.17.1): active weapon, ballistic
# offset, safety, load, CapSnap I/O, bullets, CapSnap ready.
DG_WEAPON_OPCODES = {0x0FB6, 0x0FB7, 0x0FBD, 0x0FBE, 0x0FBF, 0x0FC0, 0x0FC1, 0x0FC2, 0x0FC3,
                     0x0FC4}
WEAPON_WORDS = ('weapon', 'ballistic', 'bullet', 'safety', 'capsnap', 'trigger', 'load',
                'fire', 'arm')


def test_out_of_scope_groups_absent():
    for cmd in COMMANDS.values():
        assert not 0x0B00 <= cmd.opcode <= 0x0BFF  # weapon control unit group
        assert cmd.opcode not in DG_WEAPON_OPCODES, cmd.name
        if cmd.name.startswith('DG_'):
            assert not any(word in cmd.name.lower() for word in WEAPON_WORDS), cmd.name


def test_second_witness_settles_the_guessed_opcodes():
    """Entries the OCR lost, now taken from the Cap-Track dissector's opcode table."""
    for name, opcode in [
        ('MOT_ResetFaults', 0x0143), ('COM_Reboot', 0x0700), ('COM_GetPn', 0x0C2D),
        ('COM_GetSn', 0x0C2F), ('COM_GetHw', 0x0C4C), ('MOT_SetShortPath', 0x014E),
        ('MOT_GetShortPath', 0x014F), ('MOT_GetMaxCurrent', 0x012E),
        ('MOT_SetMaxCurrent', 0x0166), ('STB_SetSpdKp', 0x0D04), ('STB_GetSpdKp', 0x0D08),
        ('STB_SetSpdKi', 0x0D05), ('STB_GetSpdKi', 0x0D09), ('STB_SetSpdKd', 0x0D06),
        ('STB_GetSpdKd', 0x0D0A), ('STB_SetPosKp', 0x0D16), ('STB_GetPosKp', 0x0D17),
        ('STB_SetPosKi', 0x0D18), ('STB_GetPosKi', 0x0D19), ('STB_SetPosKd', 0x0D1A),
        ('STB_GetPosKd', 0x0D1B), ('STB_SaveStabilizationCfg', 0x0D07),
        ('IP_GetControllerPort', 0x070E), ('DG_SetSyncMode', 0x0FA0),
        ('DG_GoToCamera', 0x0FA9), ('DG_SetMainGimbal', 0x0FAB),
    ]:
        cmd = COMMANDS[name]
        assert cmd.opcode == opcode, name
        assert 'witness' in cmd.evidence, name
    # Nothing confirms GPS_GetLatitude: it stays a low-confidence guess.
    assert COMMANDS['GPS_GetLatitude'].confidence == 'low'


def test_new_entries_encode_with_typed_arguments():
    # ResetFaults on axis 2: 50 54 04 00 02 01 43 | checksum = 04+00+02+01+43 = 0x4A
    assert encode('MOT_ResetFaults', 2) == bytes.fromhex('505404000201434A')
    # Speed-loop Kp 1.5 on axis 1: float 0x3FC00000 big-endian (5.1.1 byte order)
    assert encode('STB_SetSpdKp', 1, 1.5) == bytes.fromhex('5054080001 0D04 3FC00000 19'
                                                           .replace(' ', ''))
    # Pelco-D: turbo speed is pan-only; the axis byte defaults to 1
    assert encode('PELCOD_SetTurboSpd', None, 90.0)[4] == 1
    with pytest.raises(ProtocolError, match='pan axis only'):
        encode('PELCOD_SetTurboSpd', 2, 90.0)
    assert encode('PELCOD_SetAxisNum', 2, 2)[5:8] == bytes([0x0C, 0x84, 2])
    # Relay module and video tracker: camera index travels in the group byte (4.11)
    assert encode('RLY_ActivateModule', None, 1)[5:8] == bytes([0x0D, 0x24, 1])
    frame = COMMANDS['VDT_setTrackingOn'].frame(2, 1)
    assert (frame.group, frame.axis, frame.opcode, frame.data) == (2, 0, 0x0A01, b'\x01')
    with pytest.raises(ProtocolError, match=r'camera index .* 4 is outside 0..3'):
        encode('VDT_isTrackingOn', 4)
    # Dual gimbals: axes 1, 2, 4, 5 only
    assert encode('DG_GetBoresightOffset', 5)[4] == 5
    with pytest.raises(ProtocolError, match='1, 2, 4, 5'):
        encode('DG_GetBoresightOffset', 3)
    with pytest.raises(ProtocolError, match=r'outside 4\.\.5'):
        encode('DG_GetCTCoffset', 1)


def test_targets_list_format():
    """5.1.5: five (width, height) uint16 pairs, 20 bytes; absent targets are (0, 0)."""
    cmd = COMMANDS['VDT_GetTargetsList']
    assert cmd.opcode == 0x0732
    data = encode_value(DataType.TARGETS, [(120, 80), (16, 9)])
    assert len(data) == 20 and data[:8] == bytes.fromhex('0078005000100009')
    reply = Frame(1, 0, 0x0732, data)
    assert cmd.decode_reply(reply) == ((120, 80), (16, 9), (0, 0), (0, 0), (0, 0))
    with pytest.raises(ProtocolError, match='expected 20 data bytes'):
        cmd.decode_reply(Frame(1, 0, 0x0732, data[:18]))
    with pytest.raises(ProtocolError, match='at most 5'):
        encode_value(DataType.TARGETS, [(1, 1)] * 6)
    with pytest.raises(ProtocolError, match=r'outside 0\.\.65535'):
        encode_value(DataType.TARGETS, [(70000, 1)])


def test_safety_classes():
    assert COMMANDS['COM_Reboot'].safety is Safety.REBOOT
    assert COMMANDS['STB_SaveStabilizationCfg'].safety is Safety.NV_WRITE
    for name in ('PELCOD_EnPelcoD', 'PELCOD_SetAddress', 'COM_SetComType',
                 'IP_SetControllerSubnetMask'):
        assert COMMANDS[name].safety is Safety.NETWORK, name
    for name in ('VDT_setTrackingOn', 'DG_GoToCamera', 'DG_SetSyncMode'):
        assert COMMANDS[name].safety is Safety.MOTION, name
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
