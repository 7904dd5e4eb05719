"""kOS data types (document section "Data Types"): big-endian scalars, String and Block.

Reconstruction decisions:
- String: the document says the UInt16 prefix counts *characters*; for UTF-8 that cannot
  delimit a field without decoding, so the length counts encoded bytes (identical for the
  ASCII text the devices use). Trailing NULs are stripped on decode ("may be null-terminated").
- Float32 values must be finite and representable; encoding NaN/inf or a magnitude beyond
  float32 raises EncodeError rather than sending garbage to a motor.
"""

from __future__ import annotations

import math
import struct

from .errors import DecodeError, EncodeError

_U8 = struct.Struct('>B')
_U16 = struct.Struct('>H')
_I32 = struct.Struct('>i')
_U32 = struct.Struct('>I')
_F32 = struct.Struct('>f')
FLOAT32_MAX = 3.4028234663852886e38


class Writer:
    """Accumulates big-endian fields; each put_* validates its range first."""

    def __init__(self) -> None:
        self._parts: list[bytes] = []

    def _int(self, packer: struct.Struct, value: int, lo: int, hi: int, what: str) -> None:
        if isinstance(value, bool):
            value = int(value)
        if not isinstance(value, int) or not lo <= value <= hi:
            raise EncodeError(f'{what} must be an integer in [{lo}, {hi}], got {value!r}')
        self._parts.append(packer.pack(value))

    def u8(self, value: int, what: str = 'UInt8') -> Writer:
        self._int(_U8, value, 0, 0xFF, what)
        return self

    def boolean(self, value: bool, what: str = 'Bool') -> Writer:
        self._parts.append(b'\x01' if value else b'\x00')
        return self

    def u16(self, value: int, what: str = 'UInt16') -> Writer:
        self._int(_U16, value, 0, 0xFFFF, what)
        return self

    def i32(self, value: int, what: str = 'Int32') -> Writer:
        self._int(_I32, value, -(2**31), 2**31 - 1, what)
        return self

    def u32(self, value: int, what: str = 'UInt32') -> Writer:
        self._int(_U32, value, 0, 2**32 - 1, what)
        return self

    def f32(self, value: float, what: str = 'Float32') -> Writer:
        try:
            value = float(value)
        except (TypeError, ValueError) as exc:
            raise EncodeError(f'{what} must be a number, got {value!r}') from exc
        if not math.isfinite(value) or abs(value) > FLOAT32_MAX:
            raise EncodeError(f'{what} must be a finite float32, got {value!r}')
        self._parts.append(_F32.pack(value))
        return self

    def raw(self, data: bytes) -> Writer:
        self._parts.append(bytes(data))
        return self

    def block(self, data: bytes, what: str = 'Block') -> Writer:
        if len(data) > 0xFFFF:
            raise EncodeError(f'{what} is {len(data)} bytes, the UInt16 prefix allows 65535')
        self.u16(len(data))
        self._parts.append(bytes(data))
        return self

    def string(self, text: str, what: str = 'String') -> Writer:
        if not isinstance(text, str):
            raise EncodeError(f'{what} must be a str, got {type(text).__name__}')
        return self.block(text.encode('utf-8'), what)

    def getvalue(self) -> bytes:
        return b''.join(self._parts)


class Reader:
    """Reads big-endian fields from a payload; running short raises DecodeError."""

    def __init__(self, data: bytes, context: str = 'payload') -> None:
        self._data = bytes(data)
        self._pos = 0
        self._context = context

    @property
    def remaining(self) -> int:
        return len(self._data) - self._pos

    def take(self, count: int, what: str = 'field') -> bytes:
        if count < 0 or self._pos + count > len(self._data):
            raise DecodeError(
                f'{self._context}: {what} needs {count} bytes at offset {self._pos}, '
                f'only {self.remaining} left'
            )
        chunk = self._data[self._pos:self._pos + count]
        self._pos += count
        return chunk

    def u8(self, what: str = 'UInt8') -> int:
        return self.take(1, what)[0]

    def boolean(self, what: str = 'Bool') -> bool:
        return self.take(1, what)[0] != 0

    def u16(self, what: str = 'UInt16') -> int:
        return _U16.unpack(self.take(2, what))[0]

    def i32(self, what: str = 'Int32') -> int:
        return _I32.unpack(self.take(4, what))[0]

    def u32(self, what: str = 'UInt32') -> int:
        return _U32.unpack(self.take(4, what))[0]

    def f32(self, what: str = 'Float32') -> float:
        return _F32.unpack(self.take(4, what))[0]

    def block(self, what: str = 'Block') -> bytes:
        length = self.u16(f'{what} length')
        return self.take(length, what)

    def string(self, what: str = 'String') -> str:
        return self.block(what).decode('utf-8', errors='replace').rstrip('\x00')

    def rest(self) -> bytes:
        return self.take(self.remaining, 'rest')

    def expect_end(self) -> None:
        if self.remaining:
            raise DecodeError(f'{self._context}: {self.remaining} unexpected trailing bytes')


def float32(value: float) -> float:
    """The value a Float32 field will carry (rounded to single precision)."""
    return _F32.unpack(_F32.pack(value))[0]
