"""Byte examples of the kOS network protocol document as test vectors.

Consistent examples (tested byte for byte, both directions):
- (Get)DeviceInfo  04 00 06 00 0F 01
- (Get)MotorInfo   04 00 06 00 0B 01
- SetPositionSpeedAcceleration, uncalibrated motor 3 to 25000 at 100/100:
  04 00 14 00 80 00 1C 03 46 C3 50 00 42 C8 00 00 42 C8 00 00
- MotorPosition(Notification) motor 3 at 11.982: 04 00 0C 00 81 02 07 03 41 3F B8 00
  (0x413FB800 = 11.982421875, the text rounds it)
- USB keep-alive 04 00 06 00 00 00 (a bare header, MessageID 0, decoded as unknown)

Inconsistent examples and the rule followed instead ("the structure wins": lengths are
recomputed from the fields, float values are taken from the hex bytes, which are self-consistent,
rather than the OCR'd decimal text):
- MotorInfo response: MessageLength 0x1C (28) but header 6 + count 1 + address 1 + 6 x Float32
  = 32 (0x20). The text says position 49.35938 and end 212.126, the bytes C2417000 / C3542040
  are -48.359375 / -212.126 (the document itself says the end may be negative); max speeds
  "10002" are 43 26 B3 33 = 166.7. Tested with length 0x20 and the byte values.
- SetPositionSpeedAcceleration, calibrated motor 1: MessageLength 0x10 (16) but the frame has
  20 bytes (same layout as the uncalibrated example, 0x14); position text 50.910 but C24BA414 is
  -50.91 (a valid target in a range ending at a negative EndPosition). Tested with 0x14 and
  -50.91.
- Block sizes of TrajectoryData (37, 21, 2, 34) all match their field lists; the Segment field
  names are garbled (see protocol/trajectory.py), the size decides them.
"""

import pytest

from kessler_kos_driver.protocol import (
    DecodeError,
    FrameParser,
    GetDeviceInfo,
    GetMotorInfo,
    MessageType,
    MotorInfo,
    MotorInfoEntry,
    MotorPosition,
    SetPositionSpeedAcceleration,
    UnknownMessage,
    decode,
    float32,
)


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text.replace(' ', ''))


def test_get_device_info_vector():
    frame = hexbytes('04 00 06 00 0F 01')
    assert GetDeviceInfo().encode() == frame
    assert isinstance(decode(frame), GetDeviceInfo)


def test_get_motor_info_vector():
    frame = hexbytes('04 00 06 00 0B 01')
    assert GetMotorInfo().encode() == frame
    assert isinstance(decode(frame), GetMotorInfo)


def test_set_position_uncalibrated_vector():
    frame = hexbytes('04 00 14 00 80 00 1C 03 46 C3 50 00 42 C8 00 00 42 C8 00 00')
    message = SetPositionSpeedAcceleration(3, 25000.0, 100.0, 100.0)
    assert message.encode() == frame
    assert decode(frame) == message


def test_motor_position_notification_vector():
    frame = hexbytes('04 00 0C 00 81 02 07 03 41 3F B8 00')
    decoded = decode(frame)
    assert isinstance(decoded, MotorPosition)
    assert decoded.motor_address == 3
    assert decoded.position == pytest.approx(11.982, abs=5e-4)
    assert decoded.encode() == frame


def test_usb_keepalive_header_is_unknown_message():
    decoded = decode(hexbytes('04 00 06 00 00 00'))
    assert isinstance(decoded, UnknownMessage)
    assert (decoded.message_id, decoded.message_type, decoded.raw_payload) == (0, 0, b'')


MOTOR_INFO_AS_PRINTED = hexbytes(
    '04 00 1C 00 0B 82 01 01 C2 41 70 00 00 00 00 00 C3 54 20 40 '
    '43 26 B3 33 43 26 B3 33 43 48 00 00'
)


def test_motor_info_example_length_as_printed_is_rejected():
    with pytest.raises(DecodeError):
        decode(MOTOR_INFO_AS_PRINTED)


def test_motor_info_example_corrected_length():
    frame = MOTOR_INFO_AS_PRINTED[:1] + b'\x00\x20' + MOTOR_INFO_AS_PRINTED[3:]
    decoded = decode(frame)
    assert isinstance(decoded, MotorInfo)
    assert decoded.more_follows and decoded.message_type == MessageType.RESPONSE_MORE
    (motor,) = decoded.motors
    assert motor.address == 1 and not motor.is_fiz
    assert motor.position == pytest.approx(-48.359375)
    assert motor.begin_position == 0.0
    assert motor.end_position == pytest.approx(-212.126, abs=1e-3)
    assert motor.calibrated
    assert motor.max_setup_speed == pytest.approx(166.7, abs=1e-4)
    assert motor.max_move_speed == pytest.approx(166.7, abs=1e-4)
    assert motor.max_acceleration == 200.0
    rebuilt = MotorInfo([MotorInfoEntry(1, -48.359375, 0.0, motor.end_position,
                                        float32(166.7), float32(166.7), 200.0)], True)
    assert rebuilt.encode() == frame


def test_motor_info_last_part_has_type_02_and_fiz_flag():
    entry = MotorInfoEntry(4, 1.0, 0.0, 0.0, 200.0, 200.0, 50.0, is_fiz=True)
    frame = MotorInfo([entry], more_follows=False).encode()
    assert frame[5] == 0x02 and frame[7] == 0x84
    decoded = decode(frame)
    assert decoded.motors[0].is_fiz and not decoded.motors[0].calibrated


def test_set_position_calibrated_example_corrected():
    printed = hexbytes('04 00 10 00 80 00 1C 01 C2 4B A4 14 42 C8 00 00 42 C8 00 00')
    with pytest.raises(DecodeError):
        decode(printed)
    corrected = printed[:2] + b'\x14' + printed[3:]
    decoded = decode(corrected)
    assert decoded.motor_address == 1
    assert decoded.position == pytest.approx(-50.910, abs=5e-4)
    assert (decoded.speed, decoded.acceleration) == (100.0, 100.0)
    assert SetPositionSpeedAcceleration(1, decoded.position, 100.0, 100.0).encode() == corrected


def test_parser_splits_the_examples_when_concatenated():
    frames = [hexbytes('04 00 06 00 0F 01'), hexbytes('04 00 0C 00 81 02 07 03 41 3F B8 00'),
              hexbytes('04 00 06 00 0B 01')]
    parser = FrameParser()
    stream = b''.join(frames)
    out = []
    for i in range(0, len(stream), 5):
        out += parser.feed(stream[i:i + 5])
    assert out == frames and parser.discarded_bytes == 0
