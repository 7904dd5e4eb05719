"""Every byte example of the Capture spec as a test vector.

Consistent examples (checksum, length and value agree) are tested byte for byte, both
ways (encode from the command table and decode back).

Wrong examples and the rule followed instead:

1. 7.1 "MOT_SetTum without data": ``50 54 04 00 01 01 3B 0x..`` repeats the opcode of
   MOT_SetPositionMode (0x013B) and its checksum byte is cut off. Rule: opcodes are unique
   and SetTum is placed by section order (0x013F, medium confidence); the example is not
   used.
2. 7.3.1/7.3.2 target LLA for target 3: printed opcode ``05 2C`` (SetInsertedLLA) but the
   checksum 0xCC only adds up with ``05 10``, which is SetTargetLLA per 5.1.3 and the
   example's own title. Rule: the checksum decides; tested with opcode 0x0510.
3. 7.3.1/7.3.2 "GPS_GoToTarget number 3": ``50 54 04 00 03 05 13 BC``: the checksum of
   04+00+03+05+13 is 0x1F, not 0xBC (no opcode near 0x0513 gives 0xBC). Rule: the
   section 2.1 checksum; opcode 0x0513 kept (single free slot, see commands.py).
4. 4.7.1/4.7.2/4.7.5: "192.168.10.13 will be sent as 0xC0, 0xA8, 0x04 (0x04A, 0x0A4),
   0x0D": 10 is 0x0A, as 4.7.6 prints. Rule: four address bytes, most significant first.
5. 7.1 "MOT_SetPosition with data of 13.487" names MOT_SendPosition (0x0132, section 2.1).
"""

from __future__ import annotations

import pytest

from capture_driver.protocol import (
    ChecksumError,
    DataType,
    GeoPoint,
    ReplyByte,
    ReplyCode,
    StreamDecoder,
    command,
    decode_frame,
    decode_value,
    encode_value,
)


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# (section, command, axis, argument, expected request bytes)
REQUEST_VECTORS = [
    ('2.1', 'MOT_GetMotorVoltage', 1, None, '50 54 04 00 01 01 07 0D'),
    ('2.2.2/7.2', 'IMU_GetRoll', None, None, '50 54 04 00 00 06 02 0C'),
    ('7.1', 'MOT_SetPositionMode', 1, None, '50 54 04 00 01 01 3B 41'),
    ('7.1', 'MOT_SetPositionRelative', 1, None, '50 54 04 00 01 01 38 3E'),
    ('7.1', 'MOT_SetAcceleration', 1, 100.0, '50 54 08 00 01 01 30 42 C8 00 00 44'),
    ('7.1', 'MOT_SetSpeed', 1, 27.78, '50 54 08 00 01 01 31 41 DE 3D 71 08'),
    ('7.1', 'MOT_SendPosition', 1, 13.487, '50 54 08 00 01 01 32 41 57 CA C1 5F'),
    ('7.1', 'MOT_Update', 1, None, '50 54 04 00 01 01 34 3A'),
    ('7.3.1', 'GPS_SetOvdPosGPS', None, 1, '50 54 05 00 00 05 31 01 3C'),
    ('7.3.2', 'GPS_SetOvdPosGPS', None, 0, '50 54 05 00 00 05 31 00 3B'),
    ('7.3.1', 'GPS_SetInsertedLLA', None, GeoPoint(34.8915, 32.1040, 65.43),
     '50 54 18 00 00 05 2C 40 41 72 1C AC 08 31 27 40 40 0D 4F DF 3B 64 5A 42 82 DC 29 E1'),
    ('7.3.1', 'GPS_SetInsertedHeading', None, 40.0, '50 54 08 00 00 05 2E 42 20 00 00 9D'),
    # Wrong example 2, with the opcode its checksum proves:
    ('7.3 corrected', 'GPS_SetTargetLLA', 3, GeoPoint(34.8921, 32.1050, 64.97),
     '50 54 18 00 03 05 10 40 41 72 30 55 32 61 7C 40 40 0D 70 A3 D7 0A 3D 42 81 F0 A4 CC'),
]

# (section, command, expected value, reply bytes)
REPLY_VECTORS = [
    ('2.1', 'MOT_GetMotorVoltage', 24.12, '50 54 08 00 01 01 07 41 C0 F5 C3 CA'),
    ('2.2.2/7.2', 'IMU_GetRoll', 30.184, '50 54 08 00 00 06 02 41 F1 78 D5 8F'),
]


@pytest.mark.parametrize(('section', 'name', 'axis', 'value', 'expected'), REQUEST_VECTORS)
def test_request_vectors_encode(section, name, axis, value, expected):
    assert command(name).encode(axis, value).hex(' ').upper() == expected, section


@pytest.mark.parametrize(('section', 'name', 'axis', 'value', 'expected'), REQUEST_VECTORS)
def test_request_vectors_decode(section, name, axis, value, expected):
    frame = decode_frame(h(expected))
    cmd = command(name)
    assert frame.opcode == cmd.opcode
    assert frame.axis == (axis or 0)
    decoded = cmd.decode_request(frame)
    if isinstance(value, float):
        assert decoded == pytest.approx(value, rel=1e-6)
    elif isinstance(value, GeoPoint):
        assert decoded.longitude == pytest.approx(value.longitude)
        assert decoded.latitude == pytest.approx(value.latitude)
        assert decoded.altitude == pytest.approx(value.altitude, rel=1e-6)
    elif value is not None:
        assert decoded == value


@pytest.mark.parametrize(('section', 'name', 'value', 'reply'), REPLY_VECTORS)
def test_reply_vectors(section, name, value, reply):
    cmd = command(name)
    frame = decode_frame(h(reply))
    assert cmd.decode_reply(frame) == pytest.approx(value, rel=1e-6)
    # The stream decoder finds the same packet, as the controller would send it.
    items = StreamDecoder().feed(h(reply))
    assert items == [frame]


def test_float_and_double_examples_5_1():
    assert encode_value(DataType.F32, -45.87) == h('C2 37 7A E1')
    assert decode_value(DataType.F32, h('C2 37 7A E1')) == pytest.approx(-45.87, rel=1e-6)
    assert encode_value(DataType.F64, 12.6492487231) == h('40 29 4C 6A 54 21 5E 57')
    assert decode_value(DataType.F64, h('40 29 4C 6A 54 21 5E 57')) == 12.6492487231


def test_lla_field_examples_7_3():
    assert encode_value(DataType.F64, 34.8915) == h('40 41 72 1C AC 08 31 27')
    assert encode_value(DataType.F64, 32.1040) == h('40 40 0D 4F DF 3B 64 5A')
    assert encode_value(DataType.F32, 65.43) == h('42 82 DC 29')
    assert encode_value(DataType.F64, 34.8921) == h('40 41 72 30 55 32 61 7C')
    assert encode_value(DataType.F64, 32.1050) == h('40 40 0D 70 A3 D7 0A 3D')
    assert encode_value(DataType.F32, 64.97) == h('42 81 F0 A4')


def test_ip_example_4_7_uses_0x0a_for_10():
    assert encode_value(DataType.IPV4, '192.168.10.13') == h('C0 A8 0A 0D')
    assert decode_value(DataType.IPV4, h('C0 A8 0A 0D')) == '192.168.10.13'


def test_checksum_example_of_section_2_1():
    # "0x04+0x01+0x01+0x07 = 0x0D": the length byte is part of the sum.
    assert h('50 54 04 00 01 01 07 0D')[-1] == (0x04 + 0x00 + 0x01 + 0x01 + 0x07)


@pytest.mark.parametrize('code', [0x06, 0x16, 0x76, 0xA6, 0xB6, 0xE6, 0xF6])
def test_reply_bytes_of_section_2_2_1(code):
    assert StreamDecoder().feed(bytes([code])) == [ReplyByte(ReplyCode(code))]


# --- the wrong examples are really wrong -------------------------------------------------

def test_wrong_example_target_lla_as_printed_fails_checksum():
    printed = h(
        '50 54 18 00 03 05 2C 40 41 72 30 55 32 61 7C 40 40 0D 70 A3 D7 0A 3D 42 81 F0 A4 CC'
    )
    with pytest.raises(ChecksumError):
        decode_frame(printed)


def test_wrong_example_goto_target_checksum():
    printed = h('50 54 04 00 03 05 13 BC')
    with pytest.raises(ChecksumError):
        decode_frame(printed)
    assert command('GPS_GoToTarget').encode(3) == h('50 54 04 00 03 05 13 1F')


def test_wrong_example_settum_is_not_settum():
    # The printed opcode byte is SetPositionMode's; SetTum has its own opcode.
    assert command('MOT_SetTum').opcode != 0x013B
    assert command('MOT_SetPositionMode').opcode == 0x013B
