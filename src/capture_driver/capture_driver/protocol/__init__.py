"""Pure-Python codec for the Capture pedestal protocol (no ROS imports).

* :mod:`.framing`   packets, checksum, ACK/NACK reply bytes, the resynchronising decoder
* :mod:`.datatypes` big-endian payload types (float, double, LLA target, preset, IPv4)
* :mod:`.commands`  the reconstructed command table with evidence and confidence
* :mod:`.registers` section 4.10 registers as named flags with severities
"""

from .commands import (
    AXIS_RULES,
    BY_OPCODE,
    COMMANDS,
    UNRESOLVED,
    AxisRule,
    Command,
    Safety,
    UnknownCommand,
    command,
    encode,
)
from .datatypes import (
    DataType,
    GeoPoint,
    PresetRecord,
    ddmm_to_degrees,
    decode_value,
    degrees_to_ddmm,
    encode_value,
)
from .framing import (
    REPLY_INFO,
    START,
    ChecksumError,
    Frame,
    FrameError,
    Garbage,
    ProtocolError,
    ReplyByte,
    ReplyCode,
    StreamDecoder,
    checksum,
    decode_frame,
    describe_reply,
    encode_frame,
)
from .registers import REGISTERS, Register

__all__ = [
    'AXIS_RULES', 'BY_OPCODE', 'COMMANDS', 'REGISTERS', 'REPLY_INFO', 'START', 'UNRESOLVED',
    'AxisRule', 'ChecksumError', 'Command', 'DataType', 'Frame', 'FrameError', 'Garbage',
    'GeoPoint', 'PresetRecord', 'ProtocolError', 'Register', 'ReplyByte', 'ReplyCode',
    'Safety', 'StreamDecoder', 'UnknownCommand', 'checksum', 'command', 'ddmm_to_degrees',
    'decode_frame', 'decode_value', 'degrees_to_ddmm', 'describe_reply', 'encode',
    'encode_frame', 'encode_value',
]
