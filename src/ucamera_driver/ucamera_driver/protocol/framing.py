"""UCSP framing: sync byte, header, payload and the 8-bit Fletcher checksum.

Packet layout (manual 5.2)::

    0      1         2   3       4 .. N+3   N+4    N+5
    0xCC   CATEGORY  ID  LENGTH  PAYLOAD    CK_A   CK_B

LENGTH counts payload bytes only, so a packet is N + 6 bytes long.

Checksum rule (reconstructed, see ``test_protocol_vectors`` for the evidence):
8-bit Fletcher (CK_A += byte; CK_B += CK_A, both mod 256) over every byte of the
packet except the two checksum bytes, *including* the 0xCC sync byte. This is the
sentence in 5.3 ("involves all the packet bytes except for the checksum bytes")
and it reproduces the three consistent examples (Save Configuration, Request
Gimbal Version, Request Telemetry Data Frequency). The generic "test packet" of
Figure 5 (CK 0xFC 0x74) and the Save FFC example (CK 0xD1 0x3E, copied from
Save Configuration) match no variant of the rule and are treated as misprints.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

SYNC_BYTE = 0xCC
HEADER_SIZE = 4
CHECKSUM_SIZE = 2
MAX_PAYLOAD = 255
OVERHEAD = HEADER_SIZE + CHECKSUM_SIZE


class ProtocolError(ValueError):
    """Base class of every error the UCSP codec raises."""


class FrameError(ProtocolError):
    """A frame could not be built or is malformed."""


def fletcher8(data: bytes | bytearray | memoryview) -> tuple[int, int]:
    """Return (CK_A, CK_B) of the UCSP 8-bit Fletcher checksum over ``data``."""
    ck_a = 0
    ck_b = 0
    for byte in data:
        ck_a = (ck_a + byte) & 0xFF
        ck_b = (ck_b + ck_a) & 0xFF
    return ck_a, ck_b


@dataclass(frozen=True)
class Frame:
    """One checksum-valid UCSP packet, payload still in device encoding."""

    category: int
    packet_id: int
    payload: bytes = b""

    @property
    def key(self) -> tuple[int, int]:
        """(category, id): what identifies the packet type."""
        return (self.category, self.packet_id)

    def encode(self) -> bytes:
        """Wire bytes of this frame."""
        return encode_frame(self.category, self.packet_id, self.payload)


def encode_frame(category: int, packet_id: int, payload: bytes = b"") -> bytes:
    """Build a complete packet (sync, header, payload, checksum)."""
    if not 0 <= category <= 0xFF:
        raise FrameError(f"category {category} does not fit in one byte")
    if not 0 <= packet_id <= 0xFF:
        raise FrameError(f"packet id {packet_id} does not fit in one byte")
    if len(payload) > MAX_PAYLOAD:
        raise FrameError(f"payload of {len(payload)} bytes exceeds the {MAX_PAYLOAD} byte limit")
    body = bytes((SYNC_BYTE, category, packet_id, len(payload))) + bytes(payload)
    return body + bytes(fletcher8(body))


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one complete packet; raise FrameError if it is not one."""
    if len(data) < OVERHEAD:
        raise FrameError(f"packet of {len(data)} bytes is shorter than the {OVERHEAD} byte minimum")
    if data[0] != SYNC_BYTE:
        raise FrameError(f"packet starts with 0x{data[0]:02X}, expected sync 0x{SYNC_BYTE:02X}")
    length = data[3]
    if len(data) != length + OVERHEAD:
        raise FrameError(
            f"length byte says {length} payload bytes, packet has {len(data) - OVERHEAD}"
        )
    expected = fletcher8(data[:-CHECKSUM_SIZE])
    received = (data[-2], data[-1])
    if expected != received:
        raise FrameError(
            "checksum mismatch: received 0x{:02X} 0x{:02X}, computed 0x{:02X} 0x{:02X}".format(
                *received, *expected
            )
        )
    return Frame(data[1], data[2], bytes(data[HEADER_SIZE:-CHECKSUM_SIZE]))


@dataclass
class ParserStats:
    """Counters of what the stream parser had to throw away."""

    frames: int = 0
    checksum_errors: int = 0
    length_errors: int = 0
    discarded_bytes: int = 0


class FrameParser:
    """Incremental UCSP stream parser that resynchronises after noise.

    Bytes arrive in arbitrary chunks. The parser looks for the sync byte, waits
    for the header and the announced payload, and checks the checksum. On any
    failure it drops only the sync byte it started from and scans again from the
    next byte, so a real packet hidden behind a false sync is still found.

    ``expected_length`` (optional) maps (category, id) to the payload length
    the packet must have, or None when unknown; a header announcing another
    length is rejected at once instead of waiting for up to 255 bytes.
    """

    def __init__(
        self,
        expected_length: Callable[[int, int], int | None] | None = None,
        max_buffer: int = 4096,
    ) -> None:
        self._buffer = bytearray()
        self._expected_length = expected_length
        self._max_buffer = max(max_buffer, MAX_PAYLOAD + OVERHEAD)
        self.stats = ParserStats()

    def reset(self) -> None:
        """Forget any partial packet (e.g. after a reconnect)."""
        self._buffer.clear()

    @property
    def pending(self) -> int:
        """Bytes held while waiting for the rest of a packet."""
        return len(self._buffer)

    def feed(self, data: bytes) -> list[Frame]:
        """Add received bytes; return every complete, valid frame found."""
        self._buffer.extend(data)
        frames: list[Frame] = []
        buf = self._buffer
        while True:
            start = buf.find(SYNC_BYTE)
            if start < 0:
                self.stats.discarded_bytes += len(buf)
                buf.clear()
                break
            if start:
                self.stats.discarded_bytes += start
                del buf[:start]
            if len(buf) < HEADER_SIZE:
                break
            category, packet_id, length = buf[1], buf[2], buf[3]
            if self._expected_length is not None:
                expected = self._expected_length(category, packet_id)
                if expected is not None and expected != length:
                    self.stats.length_errors += 1
                    self._drop_sync()
                    continue
            total = length + OVERHEAD
            if len(buf) < total:
                break
            body = buf[: total - CHECKSUM_SIZE]
            if fletcher8(body) != (buf[total - 2], buf[total - 1]):
                self.stats.checksum_errors += 1
                self._drop_sync()
                continue
            frames.append(Frame(category, packet_id, bytes(buf[HEADER_SIZE : total - 2])))
            self.stats.frames += 1
            del buf[:total]
        if len(buf) > self._max_buffer:  # cannot happen with a 255 byte maximum; keep bounded
            self.stats.discarded_bytes += len(buf)
            buf.clear()
        return frames

    def _drop_sync(self) -> None:
        self.stats.discarded_bytes += 1
        del self._buffer[:1]
