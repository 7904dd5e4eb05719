"""kOS message header and stream framing.

Header (6 bytes): ProtocolVersion UInt8 (0x04), MessageLength UInt16 (whole message including
the header), MessageID UInt16, MessageType UInt8.

Resynchronisation: TCP carries frames back to back. A candidate header is accepted only if the
version is 0x04, the length is in [6, max_frame], the MessageID's high byte is 0 (every
documented id is < 0x100) and the type is one of 0, 1, 2, 0x82. Otherwise one byte is dropped
and the search continues, so garbage in the stream costs at most the garbage itself.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from .constants import HEADER_SIZE, PROTOCOL_VERSION, MessageType
from .errors import DecodeError, EncodeError

_HEADER = struct.Struct('>BHHB')
DEFAULT_MAX_FRAME = 16384
_VALID_TYPES = frozenset(int(t) for t in MessageType)


@dataclass(frozen=True)
class Header:
    version: int
    length: int
    message_id: int
    message_type: int

    def pack(self) -> bytes:
        return _HEADER.pack(self.version, self.length, self.message_id, self.message_type)


def unpack_header(data: bytes) -> Header:
    if len(data) < HEADER_SIZE:
        raise DecodeError(f'header needs {HEADER_SIZE} bytes, got {len(data)}')
    return Header(*_HEADER.unpack_from(data, 0))


def encode_frame(message_id: int, message_type: int, payload: bytes = b'') -> bytes:
    """Header + payload; the length field is computed, never trusted from the caller."""
    length = HEADER_SIZE + len(payload)
    if length > 0xFFFF:
        raise EncodeError(f'message is {length} bytes, MessageLength (UInt16) allows 65535')
    if not 0 <= message_id <= 0xFFFF or not 0 <= message_type <= 0xFF:
        raise EncodeError(f'bad header fields id={message_id} type={message_type}')
    return _HEADER.pack(PROTOCOL_VERSION, length, message_id, message_type) + bytes(payload)


def split_frame(frame: bytes) -> tuple[Header, bytes]:
    """Check one complete frame and return (header, payload)."""
    header = unpack_header(frame)
    if header.version != PROTOCOL_VERSION:
        raise DecodeError(f'protocol version {header.version:#04x}, expected 0x04')
    if header.length != len(frame):
        raise DecodeError(
            f'MessageLength says {header.length} bytes but the frame has {len(frame)}'
        )
    return header, bytes(frame[HEADER_SIZE:])


def plausible_header(data: bytes | bytearray, max_frame: int = DEFAULT_MAX_FRAME) -> bool:
    version, length, message_id, message_type = _HEADER.unpack_from(data, 0)
    return (
        version == PROTOCOL_VERSION
        and HEADER_SIZE <= length <= max_frame
        and message_id <= 0xFF
        and message_type in _VALID_TYPES
    )


class FrameParser:
    """Incremental splitter of a kOS byte stream into complete frames."""

    def __init__(self, max_frame: int = DEFAULT_MAX_FRAME) -> None:
        self._buffer = bytearray()
        self._max_frame = max_frame
        self.discarded_bytes = 0   # garbage skipped while resynchronising

    def feed(self, data: bytes) -> list[bytes]:
        self._buffer.extend(data)
        frames: list[bytes] = []
        while len(self._buffer) >= HEADER_SIZE:
            if not plausible_header(self._buffer, self._max_frame):
                index = self._buffer.find(PROTOCOL_VERSION, 1)
                drop = index if index > 0 else len(self._buffer)
                del self._buffer[:drop]
                self.discarded_bytes += drop
                continue
            length = _HEADER.unpack_from(self._buffer, 0)[1]
            if len(self._buffer) < length:
                break
            frames.append(bytes(self._buffer[:length]))
            del self._buffer[:length]
        return frames

    def reset(self) -> None:
        self._buffer.clear()

    @property
    def pending(self) -> int:
        return len(self._buffer)
