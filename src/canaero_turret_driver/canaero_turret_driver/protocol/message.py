"""CANaerospace message: 11-bit CAN id, 4-byte header and up to 4 data bytes (ICD 4.1).

Header (CAN data bytes 0..3): node-id, data type, service code, message code; data
bytes 4..7 hold the value, big endian (ICD section 4: "Big Endian").

Frame length: the ICD says every message has "4 header bytes ... and between 1 and 4
data bytes", so frames are sent with DLC = 4 + size of the data type (NODATA: DLC 4).
The ICD examples print all eight bytes with zero padding; padded frames are accepted on
receive (extra bytes ignored) and `pad=True` produces them for devices that insist.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from .datatypes import decode_value, encode_value, payload_size, type_name
from .errors import CodecError

MAX_STANDARD_ID = 0x7FF
HEADER_SIZE = 4


class LogicalChannel(Enum):
    """Logical communication channels by CAN-id range (ICD Figure 1)."""

    EED = (0, 127)
    NSH = (128, 199)
    UDH = (200, 299)
    NOD = (300, 1799)
    UDL = (1800, 1899)
    DSD = (1900, 1999)
    NSL = (2000, 2031)

    @property
    def first_id(self) -> int:
        return self.value[0]

    @property
    def last_id(self) -> int:
        return self.value[1]


# (first id, last id, channel): channel_of runs for every received frame, and iterating the
# Enum with its properties was most of the decode time (make bench)
_CHANNEL_RANGES = tuple((c.first_id, c.last_id, c) for c in LogicalChannel)


def channel_of(can_id: int) -> LogicalChannel | None:
    """The logical channel of an 11-bit id; None for 2032..2047 (not assigned)."""
    if not 0 <= can_id <= MAX_STANDARD_ID:
        raise CodecError(f"CAN id {can_id} is not an 11-bit CAN 2.0A identifier")
    for first_id, last_id, channel in _CHANNEL_RANGES:
        if first_id <= can_id <= last_id:
            return channel
    return None


def _check_byte(name: str, value: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 255:
        raise CodecError(f"{name} must be 0..255, got {value!r}")
    return value


@dataclass(frozen=True)
class CanAerospaceMessage:
    """One CANaerospace message as carried by one CAN 2.0A frame."""

    can_id: int
    node_id: int
    data_type: int
    service_code: int = 0
    message_code: int = 0
    payload: bytes = b""

    def __post_init__(self) -> None:
        channel_of(self.can_id)
        _check_byte("node-id", self.node_id)
        _check_byte("data type", self.data_type)
        _check_byte("service code", self.service_code)
        _check_byte("message code", self.message_code)
        if len(self.payload) > 4:
            raise CodecError(f"at most 4 data bytes fit a message, got {len(self.payload)}")

    @classmethod
    def build(
        cls,
        can_id: int,
        node_id: int,
        data_type: int,
        value: object = None,
        service_code: int = 0,
        message_code: int = 0,
    ) -> CanAerospaceMessage:
        """Encode `value` as `data_type` into a message."""
        return cls(can_id, node_id, int(data_type), service_code, message_code,
                   encode_value(data_type, value))

    @classmethod
    def from_frame(cls, can_id: int, data: bytes | bytearray) -> CanAerospaceMessage:
        """Parse a received frame; raises CodecError (never anything else) when malformed."""
        data = bytes(data)
        if len(data) < HEADER_SIZE:
            raise CodecError(
                f"frame 0x{can_id:03X} has {len(data)} data bytes, a CANaerospace header "
                "needs 4"
            )
        if len(data) > 8:
            raise CodecError(f"frame 0x{can_id:03X} has {len(data)} bytes, CAN 2.0 max is 8")
        node_id, data_type, service_code, message_code = data[:HEADER_SIZE]
        payload = data[HEADER_SIZE:]
        size = payload_size(data_type)
        if size is not None:
            if len(payload) < size:
                raise CodecError(
                    f"frame 0x{can_id:03X} says {type_name(data_type)} ({size} data bytes) "
                    f"but carries {len(payload)}"
                )
            payload = payload[:size]
        return cls(can_id, node_id, data_type, service_code, message_code, payload)

    @property
    def channel(self) -> LogicalChannel | None:
        return channel_of(self.can_id)

    @property
    def type_name(self) -> str:
        return type_name(self.data_type)

    @property
    def value(self) -> object:
        """The payload decoded according to the header's data type."""
        return decode_value(self.data_type, self.payload)

    def to_bytes(self, pad: bool = False) -> bytes:
        """Header + data bytes; `pad` fills up to 8 bytes with zeros."""
        raw = bytes((self.node_id, self.data_type, self.service_code, self.message_code))
        raw += self.payload
        if pad:
            raw = raw.ljust(8, b"\x00")
        return raw

    def describe(self) -> str:
        """Short text for logs."""
        try:
            shown = repr(self.value)
        except CodecError:
            shown = self.payload.hex()
        return (f"id={self.can_id} node={self.node_id} type={self.type_name} "
                f"svc={self.service_code} code={self.message_code} value={shown}")

