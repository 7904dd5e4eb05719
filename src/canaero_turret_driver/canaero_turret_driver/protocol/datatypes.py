"""CANaerospace data types (ICD section 3): type codes and big-endian value codecs.

Reconstruction notes (the ICD is OCR text):

* Type codes 24..31 are printed with the hex "(0x17)" in every row. The decimal codes
  24..31 are consecutive and agree with the published CANaerospace 1.7 list
  (ACHAR2 = 24 ... DOUBLEL = 31), so the decimal value is used and the hex is an OCR
  copy of the ACHAR row.
* LONG's range is printed "-2147483647 to 2147483648"; a 32-bit two's complement
  integer spans -2147483648 .. 2147483647 (section text: "2's complement integer").
* ACHAR3 is explained as "4 x ASCII character" but its Bits column says 3 x 8 and its
  name says 3: three characters.
* RESVD is 32-99 and UDEF is printed "102-255 (0x66-0xFF)", which would leave 100-101
  unassigned; CANaerospace 1.7 and libcanaerospace (``CANAS_DATATYPE_UDEF_BEGIN_ =
  100``) start the user-defined types at 100, so 100-255 are UDEF here (`type_name`).
  Types >= 32 have no codec here: their payload is kept as raw bytes.
* ERROR (type 1) is the EED payload; its layout is in `eed.py`.

Value representation: scalar types are `int`/`float`, multi-value types a tuple of ints,
ACHARn a `str` of n latin-1 characters, ERROR a tuple (error_code, operation_id,
location_id), DOUBLEH/DOUBLEL the raw 32-bit half (see `split_double`/`join_double`).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum

from .errors import CodecError


class DataType(IntEnum):
    """Type numbers carried in header byte 1."""

    NODATA = 0
    ERROR = 1
    FLOAT = 2
    LONG = 3
    ULONG = 4
    BLONG = 5
    SHORT = 6
    USHORT = 7
    BSHORT = 8
    CHAR = 9
    UCHAR = 10
    BCHAR = 11
    SHORT2 = 12
    USHORT2 = 13
    BSHORT2 = 14
    CHAR4 = 15
    UCHAR4 = 16
    BCHAR4 = 17
    CHAR2 = 18
    UCHAR2 = 19
    BCHAR2 = 20
    MEMID = 21
    CHKSUM = 22
    ACHAR = 23
    ACHAR2 = 24
    ACHAR4 = 25
    CHAR3 = 26
    UCHAR3 = 27
    BCHAR3 = 28
    ACHAR3 = 29
    DOUBLEH = 30
    DOUBLEL = 31


@dataclass(frozen=True)
class TypeCodec:
    """How one data type maps onto the data bytes 4..7."""

    data_type: DataType
    struct_format: str  # big-endian struct format of the payload ('' = no payload)
    kind: str  # 'none', 'float', 'int', 'tuple', 'ascii', 'error'

    @property
    def size(self) -> int:
        return struct.calcsize(self.struct_format) if self.struct_format else 0

    @property
    def count(self) -> int:
        """Number of values packed in the payload."""
        if not self.struct_format:
            return 0
        return len(struct.unpack(self.struct_format, bytes(self.size)))


_CODECS: dict[DataType, TypeCodec] = {
    codec.data_type: codec
    for codec in (
        TypeCodec(DataType.NODATA, "", "none"),
        TypeCodec(DataType.ERROR, ">HBB", "error"),
        TypeCodec(DataType.FLOAT, ">f", "float"),
        TypeCodec(DataType.LONG, ">i", "int"),
        TypeCodec(DataType.ULONG, ">I", "int"),
        TypeCodec(DataType.BLONG, ">I", "int"),
        TypeCodec(DataType.SHORT, ">h", "int"),
        TypeCodec(DataType.USHORT, ">H", "int"),
        TypeCodec(DataType.BSHORT, ">H", "int"),
        TypeCodec(DataType.CHAR, ">b", "int"),
        TypeCodec(DataType.UCHAR, ">B", "int"),
        TypeCodec(DataType.BCHAR, ">B", "int"),
        TypeCodec(DataType.SHORT2, ">2h", "tuple"),
        TypeCodec(DataType.USHORT2, ">2H", "tuple"),
        TypeCodec(DataType.BSHORT2, ">2H", "tuple"),
        TypeCodec(DataType.CHAR4, ">4b", "tuple"),
        TypeCodec(DataType.UCHAR4, ">4B", "tuple"),
        TypeCodec(DataType.BCHAR4, ">4B", "tuple"),
        TypeCodec(DataType.CHAR2, ">2b", "tuple"),
        TypeCodec(DataType.UCHAR2, ">2B", "tuple"),
        TypeCodec(DataType.BCHAR2, ">2B", "tuple"),
        TypeCodec(DataType.MEMID, ">I", "int"),
        TypeCodec(DataType.CHKSUM, ">I", "int"),
        TypeCodec(DataType.ACHAR, ">1s", "ascii"),
        TypeCodec(DataType.ACHAR2, ">2s", "ascii"),
        TypeCodec(DataType.ACHAR4, ">4s", "ascii"),
        TypeCodec(DataType.CHAR3, ">3b", "tuple"),
        TypeCodec(DataType.UCHAR3, ">3B", "tuple"),
        TypeCodec(DataType.BCHAR3, ">3B", "tuple"),
        TypeCodec(DataType.ACHAR3, ">3s", "ascii"),
        TypeCodec(DataType.DOUBLEH, ">I", "int"),
        TypeCodec(DataType.DOUBLEL, ">I", "int"),
    )
}

# Integer ranges per struct letter, for clear range errors before packing.
_INT_RANGES = {
    "b": (-128, 127),
    "B": (0, 255),
    "h": (-32768, 32767),
    "H": (0, 65535),
    "i": (-2147483648, 2147483647),
    "I": (0, 4294967295),
}

FLOAT32_MAX = 3.4028234663852886e38


def type_name(code: int) -> str:
    """Human name of a type code, also for reserved (32-99) and user-defined (100-255)
    codes."""
    try:
        return DataType(code).name
    except ValueError:
        if 32 <= code <= 99:
            return f"RESVD({code})"
        return f"UDEF({code})"


def codec_for(code: int) -> TypeCodec | None:
    """The codec of a known type code, None for reserved/user-defined codes."""
    try:
        return _CODECS[DataType(code)]
    except ValueError:
        return None


def payload_size(code: int) -> int | None:
    """Number of data bytes the type occupies (None: unknown type)."""
    codec = codec_for(code)
    return None if codec is None else codec.size


def _check_int(name: str, letter: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise CodecError(f"{name} needs an integer, got {value!r}")
    low, high = _INT_RANGES[letter]
    if not low <= value <= high:
        raise CodecError(f"{name} value {value} is outside {low}..{high}")
    return value


def encode_value(code: int, value: object) -> bytes:
    """Pack `value` as data type `code` (big endian). Raises CodecError on a bad value."""
    codec = codec_for(code)
    if codec is None:
        if isinstance(value, bytes | bytearray) and len(value) <= 4:
            return bytes(value)
        raise CodecError(f"type {type_name(code)} has no codec: pass at most 4 raw bytes")
    name = codec.data_type.name
    letters = codec.struct_format.lstrip(">")
    if codec.kind == "none":
        if value not in (None, (), b""):
            raise CodecError(f"NODATA carries no value, got {value!r}")
        return b""
    if codec.kind == "float":
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CodecError(f"{name} needs a number, got {value!r}")
        number = float(value)
        if math.isfinite(number) and abs(number) > FLOAT32_MAX:
            raise CodecError(f"{name} value {number} does not fit a 32-bit float")
        return struct.pack(">f", number)
    if codec.kind == "int":
        return struct.pack(codec.struct_format, _check_int(name, letters, value))
    if codec.kind == "ascii":
        size = codec.size
        if isinstance(value, str):
            try:
                raw = value.encode("latin-1")
            except UnicodeEncodeError as exc:
                raise CodecError(f"{name} needs 8-bit characters, got {value!r}") from exc
        elif isinstance(value, bytes | bytearray):
            raw = bytes(value)
        else:
            raise CodecError(f"{name} needs a string, got {value!r}")
        if len(raw) != size:
            raise CodecError(f"{name} needs exactly {size} characters, got {len(raw)}")
        return raw
    # tuple and error kinds: one value per struct letter
    count = len(letters) if codec.kind == "error" else codec.count
    if not isinstance(value, tuple | list) or len(value) != count:
        raise CodecError(f"{name} needs {count} values, got {value!r}")
    if codec.kind == "error":
        checked = [
            _check_int(f"{name}[{index}]", letter, item)
            for index, (letter, item) in enumerate(zip(letters, value, strict=True))
        ]
    else:
        letter = letters[-1]
        checked = [_check_int(f"{name}[{index}]", letter, item) for index, item in
                   enumerate(value)]
    return struct.pack(codec.struct_format, *checked)


def decode_value(code: int, payload: bytes) -> object:
    """Unpack data bytes as type `code`.

    Extra trailing bytes (frames padded to 8 bytes, as the ICD examples show) are
    ignored; too few bytes raise CodecError. Unknown types return the raw bytes.
    """
    codec = codec_for(code)
    if codec is None:
        return bytes(payload)
    size = codec.size
    if len(payload) < size:
        raise CodecError(
            f"{codec.data_type.name} needs {size} data bytes, the frame has {len(payload)}"
        )
    if codec.kind == "none":
        return None
    values = struct.unpack(codec.struct_format, bytes(payload[:size]))
    if codec.kind == "ascii":
        return values[0].decode("latin-1")
    if codec.kind in ("float", "int"):
        return values[0]
    return tuple(values)


def split_double(value: float) -> tuple[int, int]:
    """A 64-bit double as (DOUBLEH, DOUBLEL) raw halves."""
    raw = struct.unpack(">Q", struct.pack(">d", value))[0]
    return raw >> 32, raw & 0xFFFFFFFF


def join_double(high: int, low: int) -> float:
    """Rebuild a double from its DOUBLEH and DOUBLEL halves."""
    return struct.unpack(">d", struct.pack(">Q", (high << 32) | low))[0]
