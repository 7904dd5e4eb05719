"""Capture packet framing (spec section 2): build, check and split a byte stream.

Wire format (section 2.1, table 1)::

    0x50 0x54 | length | group | axis | opcode high | opcode low | data ... | checksum

* ``length`` = number of data bytes + 4 (group, axis and the two opcode bytes);
  0x04 for a packet without data (section 2.1, "Length byte is determined by
  the number of data bytes + 4").
* ``checksum`` = low byte of the sum of every byte after the two start bytes
  (length, group, axis, opcode, data). Section 2.1 words it as "all the bytes
  except the two Start Bytes and the Check Sum"; the worked example
  ``0x04+0x01+0x01+0x07 = 0x0D`` confirms that the length byte is included.
* Data is big-endian (section 5.1).

Replies are either a data packet with the request's opcode (section 2.2.2) or
a single reply byte (section 2.2.1): ACK 0x06 or one of six NACK codes. The
:class:`StreamDecoder` separates the three kinds of input (packets, reply
bytes, garbage) and resynchronises after garbage, a corrupted byte or a lost
byte by rescanning from the byte after a failed start.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

START = b'\x50\x54'
START1, START2 = START
HEADER_SIZE = 4  # group, axis, opcode high, opcode low
MAX_DATA_SIZE = 0xFF - HEADER_SIZE
MIN_PACKET_SIZE = len(START) + 1 + HEADER_SIZE + 1


class ProtocolError(ValueError):
    """Base class of every error the Capture codec raises."""


class FrameError(ProtocolError):
    """A byte sequence is not a valid Capture packet."""


class ChecksumError(FrameError):
    """A packet's checksum byte does not match its content."""


def checksum(body: bytes) -> int:
    """Low byte of the sum of ``body`` (length byte through the last data byte)."""
    return sum(body) & 0xFF


@dataclass(frozen=True)
class Frame:
    """One Capture packet; ``data`` holds the raw big-endian payload."""

    group: int
    axis: int
    opcode: int
    data: bytes = b''

    def __post_init__(self) -> None:
        for label, value, limit in (
            ('group', self.group, 0xFF),
            ('axis', self.axis, 0xFF),
            ('opcode', self.opcode, 0xFFFF),
        ):
            if not isinstance(value, int) or not 0 <= value <= limit:
                raise FrameError(f'{label} {value!r} is outside 0..{limit:#x}')
        if len(self.data) > MAX_DATA_SIZE:
            raise FrameError(f'{len(self.data)} data bytes exceed the maximum of {MAX_DATA_SIZE}')

    def encode(self) -> bytes:
        """The packet's bytes, computed once (the joint poll writes the same four frames at
        every tick; a frozen dataclass keeps them with ``object.__setattr__``)."""
        wire: bytes | None = self.__dict__.get('wire')
        if wire is None:
            wire = self._encode()
            object.__setattr__(self, 'wire', wire)
        return wire

    def _encode(self) -> bytes:
        body = bytes(
            (
                len(self.data) + HEADER_SIZE,
                self.group,
                self.axis,
                self.opcode >> 8,
                self.opcode & 0xFF,
            )
        ) + bytes(self.data)
        return START + body + bytes((checksum(body),))

    def __str__(self) -> str:
        return (
            f'Frame(group={self.group}, axis={self.axis}, opcode=0x{self.opcode:04X}, '
            f'data={self.data.hex(" ") or "-"})'
        )


def encode_frame(group: int, axis: int, opcode: int, data: bytes = b'') -> bytes:
    """Bytes of one packet."""
    return Frame(group, axis, opcode, bytes(data)).encode()


def decode_frame(packet: bytes) -> Frame:
    """Parse exactly one complete packet; raises :class:`FrameError` with the reason."""
    packet = bytes(packet)
    if len(packet) < MIN_PACKET_SIZE:
        raise FrameError(
            f'{len(packet)} bytes is shorter than the minimum packet ({MIN_PACKET_SIZE})'
        )
    if packet[:2] != START:
        raise FrameError(f'packet starts with {packet[:2].hex(" ")}, expected 50 54')
    length = packet[2]
    if length < HEADER_SIZE:
        raise FrameError(f'length byte {length:#04x} is below the minimum 0x04')
    expected = len(START) + 1 + length + 1
    if len(packet) != expected:
        raise FrameError(
            f'length byte {length:#04x} means {expected} packet bytes, got {len(packet)}'
        )
    body = packet[2:-1]
    if checksum(body) != packet[-1]:
        raise ChecksumError(
            f'checksum {packet[-1]:#04x} does not match the content '
            f'(expected {checksum(body):#04x})'
        )
    return Frame(body[1], body[2], (body[3] << 8) | body[4], bytes(body[5:]))


class ReplyCode(IntEnum):
    """Single-byte replies (section 2.2.1 table and chapter 7 list)."""

    ACK = 0x06
    PEDESTAL_UNAVAILABLE = 0x16
    VIDEO_TRACKER_UNAVAILABLE = 0x76
    INVALID_COMMAND = 0xA6
    INVALID_MOTOR_CHECKSUM = 0xB6
    EXECUTION_ERROR = 0xE6
    WRONG_CHECKSUM = 0xF6


@dataclass(frozen=True)
class ReplyInfo:
    title: str
    meaning: str
    advice: str


REPLY_INFO: dict[ReplyCode, ReplyInfo] = {
    ReplyCode.ACK: ReplyInfo('Acknowledge', 'the command is valid and had a correct checksum', ''),
    ReplyCode.PEDESTAL_UNAVAILABLE: ReplyInfo(
        'Pedestal unavailable',
        'the motor controllers are unavailable',
        'power cycle the pedestal; if the error remains, contact Capture support',
    ),
    ReplyCode.VIDEO_TRACKER_UNAVAILABLE: ReplyInfo(
        'Video tracker unavailable',
        'the video tracker is not available (systems with a video tracker only)',
        'power cycle the pedestal; if the error remains, contact Capture support',
    ),
    ReplyCode.INVALID_COMMAND: ReplyInfo(
        'Invalid command',
        'the controller cannot handle the command in its current configuration or mode '
        '(e.g. a motor command while scanning, stabilising, tracking or homing)',
        'check that the command is valid for this system and mode; '
        'ERR_GetProtocolErrorString gives the reason',
    ),
    ReplyCode.INVALID_MOTOR_CHECKSUM: ReplyInfo(
        'Invalid motor checksum',
        'communication error between the Cap-Track controller and the motor controllers',
        'power cycle the pedestal; if the error remains, contact Capture support',
    ),
    ReplyCode.EXECUTION_ERROR: ReplyInfo(
        'Execution error',
        'general error while executing the command',
        'power cycle the pedestal; if the error remains, contact Capture support',
    ),
    ReplyCode.WRONG_CHECKSUM: ReplyInfo(
        'Wrong checksum',
        'the controller received a packet with a wrong checksum and did not execute it',
        'check the link for noise or lost bytes (the driver resends nothing by itself)',
    ),
}

REPLY_BYTES = frozenset(int(code) for code in ReplyCode)


def describe_reply(code: int) -> str:
    """One line for logs and service answers, e.g. ``NACK 0xA6 Invalid command: ...``."""
    try:
        reply = ReplyCode(code)
    except ValueError:
        return f'unknown reply byte {code:#04x}'
    info = REPLY_INFO[reply]
    if reply == ReplyCode.ACK:
        return 'ACK 0x06'
    return f'NACK {code:#04X} {info.title}: {info.meaning}; {info.advice}'


@dataclass(frozen=True)
class ReplyByte:
    """A single ACK/NACK byte found in the stream."""

    code: ReplyCode

    @property
    def is_ack(self) -> bool:
        return self.code == ReplyCode.ACK


@dataclass(frozen=True)
class Garbage:
    """Bytes the decoder discarded (noise, a corrupted packet's first byte, ...)."""

    data: bytes
    reason: str


StreamItem = Frame | ReplyByte | Garbage


class StreamDecoder:
    """Incremental decoder for the controller-to-host (or host-to-controller) stream.

    ``feed`` returns every complete item in arrival order. A packet whose
    checksum fails is not thrown away whole: only its first byte is dropped and
    scanning restarts right after it, so a packet that follows a truncated one
    (a lost byte) is still found. ``flush_partial`` gives up on a started packet
    that never completes (call it when the line has been quiet for a while).
    """

    def __init__(self, max_buffer: int = 4096) -> None:
        self._buffer = bytearray()
        self._max_buffer = max_buffer
        self.frames = 0
        self.reply_bytes = 0
        self.garbage_bytes = 0
        self.checksum_errors = 0

    @property
    def has_partial(self) -> bool:
        """True when bytes of an unfinished packet are waiting."""
        return bool(self._buffer)

    def reset(self) -> None:
        self._buffer.clear()

    def feed(self, data: bytes) -> list[StreamItem]:
        self._buffer += data
        items: list[StreamItem] = []
        self._scan(items, flush=False)
        if len(self._buffer) > self._max_buffer:
            items.extend(self.flush_partial())
        return items

    def flush_partial(self) -> list[StreamItem]:
        """Drop the first byte of a pending partial packet and rescan the rest."""
        items: list[StreamItem] = []
        self._scan(items, flush=True)
        return items

    def _discard(self, items: list[StreamItem], count: int, reason: str) -> None:
        dropped = bytes(self._buffer[:count])
        del self._buffer[:count]
        self.garbage_bytes += len(dropped)
        if items and isinstance(items[-1], Garbage) and items[-1].reason == reason:
            items[-1] = Garbage(items[-1].data + dropped, reason)
        else:
            items.append(Garbage(dropped, reason))

    def _scan(self, items: list[StreamItem], flush: bool) -> None:
        buf = self._buffer
        while buf:
            first = buf[0]
            if first in REPLY_BYTES:
                del buf[0]
                self.reply_bytes += 1
                items.append(ReplyByte(ReplyCode(first)))
                continue
            if first != START1:
                end = 1
                while end < len(buf) and buf[end] != START1 and buf[end] not in REPLY_BYTES:
                    end += 1
                self._discard(items, end, 'noise')
                continue
            if len(buf) < 2 or (len(buf) >= 2 and buf[1] == START2 and len(buf) < 3):
                if flush:
                    self._discard(items, 1, 'incomplete packet')
                    flush = False
                    continue
                return
            if buf[1] != START2:
                self._discard(items, 1, 'noise')
                continue
            length = buf[2]
            if length < HEADER_SIZE:
                self._discard(items, 1, 'bad length byte')
                continue
            total = len(START) + 1 + length + 1
            if len(buf) < total:
                if flush:
                    self._discard(items, 1, 'incomplete packet')
                    flush = False
                    continue
                return
            body = bytes(buf[2 : total - 1])
            if checksum(body) != buf[total - 1]:
                self.checksum_errors += 1
                self._discard(items, 1, 'checksum mismatch')
                continue
            del buf[:total]
            self.frames += 1
            items.append(Frame(body[1], body[2], (body[3] << 8) | body[4], body[5:]))
