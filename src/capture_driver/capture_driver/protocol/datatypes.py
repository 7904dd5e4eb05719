"""Payload encodings of the Capture protocol (sections 2 and 5.1), all big-endian.

Composite formats:

* Target LLA (5.1.3): longitude f64, latitude f64 (decimal degrees), altitude f32 (m); 20 bytes.
* Preset (5.1.4): 16-byte ASCII name, then azimuth, elevation, roll, X, Y, Z as f32 degrees;
  40 bytes. (PRST_GetPreset/SetPreset refer to "section 5.1.5" for it; 5.1.5 is the
  targets list, so the reference is off by one and 5.1.4 is meant.)
* Targets list (5.1.5, GetTargetsList 0x0732): five (width, height) uint16 pairs, 20 bytes;
  absent targets are (0, 0).
* IPv4 (4.7): four bytes, most significant first (192.168.10.13 -> C0 A8 0A 0D; the
  examples in 4.7.1/4.7.2/4.7.5 printing 0x04/0x04A/0x0A4 for the third byte are OCR errors,
  4.7.6 prints the consistent 0x0A).

The GPS position getters (4.4.1, 4.4.2) return DDMM.mmmm (degrees and decimal minutes),
unlike the target format, which is decimal degrees; :func:`ddmm_to_degrees` converts.
"""

from __future__ import annotations

import ipaddress
import math
import struct
from dataclasses import dataclass
from enum import Enum
from typing import Any

from .framing import ProtocolError


class DataType(Enum):
    """Payload types named in the command descriptions."""

    NONE = 'none'
    U8 = 'uint8'
    BOOL = 'bool'  # "single byte (value of 0 or 1)"
    U16 = 'uint16'
    U32 = 'uint32'
    F32 = 'float32'
    F64 = 'float64'
    ASCII = 'ascii'
    IPV4 = 'ipv4'
    LLA = 'target_lla'
    PRESET = 'preset'
    TARGETS = 'targets_list'  # 5.1.5: five (width, height) uint16 pairs


PRESET_NAME_SIZE = 16
TARGETS_LIST_SIZE = 5  # 5.1.5: "the system can hold up to 5 targets at once"
PRESET_AXES = ('azimuth', 'elevation', 'roll', 'x', 'y', 'z')
_LLA = struct.Struct('>ddf')
_PRESET = struct.Struct(f'>{PRESET_NAME_SIZE}s6f')
_TARGETS = struct.Struct(f'>{2 * TARGETS_LIST_SIZE}H')

FIXED_SIZES: dict[DataType, int] = {
    DataType.NONE: 0,
    DataType.U8: 1,
    DataType.BOOL: 1,
    DataType.U16: 2,
    DataType.U32: 4,
    DataType.F32: 4,
    DataType.F64: 8,
    DataType.IPV4: 4,
    DataType.LLA: _LLA.size,
    DataType.PRESET: _PRESET.size,
    DataType.TARGETS: _TARGETS.size,
}

_FLOAT32_MAX = 3.4028234663852886e38


@dataclass(frozen=True)
class GeoPoint:
    """A target or system position in the Target LLA format."""

    longitude: float  # decimal degrees, east positive
    latitude: float  # decimal degrees, north positive
    altitude: float  # metres


@dataclass(frozen=True)
class PresetRecord:
    """A device preset; angles in degrees as read by MOT_GetLoadPosition."""

    name: str
    angles: tuple[float, float, float, float, float, float] = (0.0,) * 6


def _need_number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ProtocolError(f'{what} needs a number, got {value!r}')
    if not math.isfinite(value):
        raise ProtocolError(f'{what} needs a finite number, got {value!r}')
    return float(value)


def _need_int(value: Any, low: int, high: int, what: str) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool):
        value = int(value)
    if not isinstance(value, int):
        raise ProtocolError(f'{what} needs an integer, got {value!r}')
    if not low <= value <= high:
        raise ProtocolError(f'{what} {value} is outside {low}..{high}')
    return value


def _f32(value: Any, what: str) -> bytes:
    number = _need_number(value, what)
    if abs(number) > _FLOAT32_MAX:
        raise ProtocolError(f'{what} {number} does not fit a 32-bit float')
    return struct.pack('>f', number)


def encode_value(dtype: DataType, value: Any, what: str = 'value') -> bytes:
    """Payload bytes for ``value``; raises :class:`ProtocolError` naming ``what``."""
    if dtype is DataType.NONE:
        if value is not None:
            raise ProtocolError(f'{what} takes no argument, got {value!r}')
        return b''
    if value is None:
        raise ProtocolError(f'{what} needs a {dtype.value} argument')
    if dtype is DataType.U8:
        return bytes((_need_int(value, 0, 0xFF, what),))
    if dtype is DataType.BOOL:
        return bytes((_need_int(value, 0, 1, what),))
    if dtype is DataType.U16:
        return struct.pack('>H', _need_int(value, 0, 0xFFFF, what))
    if dtype is DataType.U32:
        return struct.pack('>I', _need_int(value, 0, 0xFFFFFFFF, what))
    if dtype is DataType.F32:
        return _f32(value, what)
    if dtype is DataType.F64:
        return struct.pack('>d', _need_number(value, what))
    if dtype is DataType.ASCII:
        if not isinstance(value, str) or not value.isascii():
            raise ProtocolError(f'{what} needs an ASCII string, got {value!r}')
        return value.encode('ascii')
    if dtype is DataType.IPV4:
        try:
            return ipaddress.IPv4Address(value).packed
        except (ipaddress.AddressValueError, ValueError, TypeError) as exc:
            raise ProtocolError(f'{what} needs an IPv4 address, got {value!r}') from exc
    if dtype is DataType.LLA:
        point = value if isinstance(value, GeoPoint) else _geo_from(value, what)
        if not -180.0 <= point.longitude <= 180.0 or not -90.0 <= point.latitude <= 90.0:
            raise ProtocolError(f'{what}: longitude/latitude {point} out of range')
        return _LLA.pack(
            _need_number(point.longitude, f'{what} longitude'),
            _need_number(point.latitude, f'{what} latitude'),
            struct.unpack('>f', _f32(point.altitude, f'{what} altitude'))[0],
        )
    if dtype is DataType.PRESET:
        record = value if isinstance(value, PresetRecord) else _preset_from(value, what)
        name = record.name.encode('ascii', errors='replace')
        if len(name) > PRESET_NAME_SIZE:
            raise ProtocolError(f'{what}: preset name longer than {PRESET_NAME_SIZE} characters')
        angles = [
            struct.unpack('>f', _f32(a, f'{what} {axis}'))[0]
            for axis, a in zip(PRESET_AXES, record.angles, strict=True)
        ]
        return _PRESET.pack(name.ljust(PRESET_NAME_SIZE, b'\0'), *angles)
    if dtype is DataType.TARGETS:
        return _TARGETS.pack(*_targets_from(value, what))
    raise ProtocolError(f'unsupported data type {dtype}')  # pragma: no cover


def _targets_from(value: Any, what: str) -> list[int]:
    """Flatten up to five (width, height) pairs; missing targets are (0, 0) (5.1.5)."""
    try:
        pairs = [tuple(pair) for pair in value]
    except TypeError as exc:
        raise ProtocolError(f'{what} needs (width, height) pairs, got {value!r}') from exc
    if len(pairs) > TARGETS_LIST_SIZE or any(len(pair) != 2 for pair in pairs):
        raise ProtocolError(f'{what} needs at most {TARGETS_LIST_SIZE} (width, height) pairs')
    pairs += [(0, 0)] * (TARGETS_LIST_SIZE - len(pairs))
    return [_need_int(v, 0, 0xFFFF, f'{what} target size') for pair in pairs for v in pair]


def _geo_from(value: Any, what: str) -> GeoPoint:
    try:
        lon, lat, alt = value
    except (TypeError, ValueError) as exc:
        raise ProtocolError(f'{what} needs (longitude, latitude, altitude), got {value!r}') from exc
    return GeoPoint(
        _need_number(lon, f'{what} longitude'),
        _need_number(lat, f'{what} latitude'),
        _need_number(alt, f'{what} altitude'),
    )


def _preset_from(value: Any, what: str) -> PresetRecord:
    try:
        name, angles = value
        angles = tuple(float(a) for a in angles)
    except (TypeError, ValueError) as exc:
        raise ProtocolError(f'{what} needs (name, [6 angles]), got {value!r}') from exc
    if len(angles) != 6 or not isinstance(name, str):
        raise ProtocolError(f'{what} needs a name and 6 angles, got {value!r}')
    return PresetRecord(name, angles)


def decode_value(dtype: DataType, data: bytes, what: str = 'reply') -> Any:
    """Value of a payload; raises :class:`ProtocolError` for a wrong size or content."""
    data = bytes(data)
    size = FIXED_SIZES.get(dtype)
    if size is not None and len(data) != size:
        raise ProtocolError(
            f'{what}: expected {size} data bytes for {dtype.value}, got {len(data)}'
        )
    if dtype is DataType.NONE:
        return None
    if dtype is DataType.U8:
        return data[0]
    if dtype is DataType.BOOL:
        return bool(data[0])
    if dtype is DataType.U16:
        return struct.unpack('>H', data)[0]
    if dtype is DataType.U32:
        return struct.unpack('>I', data)[0]
    if dtype is DataType.F32:
        return struct.unpack('>f', data)[0]
    if dtype is DataType.F64:
        return struct.unpack('>d', data)[0]
    if dtype is DataType.ASCII:
        return data.split(b'\0', 1)[0].decode('ascii', errors='replace').strip()
    if dtype is DataType.IPV4:
        return str(ipaddress.IPv4Address(data))
    if dtype is DataType.LLA:
        return GeoPoint(*_LLA.unpack(data))
    if dtype is DataType.PRESET:
        raw_name, *angles = _PRESET.unpack(data)
        name = raw_name.split(b'\0', 1)[0].decode('ascii', errors='replace')
        return PresetRecord(name, tuple(angles))
    if dtype is DataType.TARGETS:
        values = _TARGETS.unpack(data)
        return tuple(zip(values[0::2], values[1::2], strict=True))
    raise ProtocolError(f'unsupported data type {dtype}')  # pragma: no cover


def ddmm_to_degrees(value: float) -> float:
    """DDMM.mmmm (degrees*100 + decimal minutes, signed) to decimal degrees."""
    if not math.isfinite(value):
        raise ProtocolError(f'GPS coordinate {value} is not finite')
    sign = -1.0 if value < 0 else 1.0
    magnitude = abs(value)
    degrees = math.floor(magnitude / 100.0)
    minutes = magnitude - degrees * 100.0
    if minutes >= 60.0 + 1e-9:
        raise ProtocolError(f'GPS coordinate {value}: minutes {minutes:.4f} >= 60')
    return sign * (degrees + minutes / 60.0)


def degrees_to_ddmm(value: float) -> float:
    """Decimal degrees to DDMM.mmmm (used by the simulator)."""
    sign = -1.0 if value < 0 else 1.0
    magnitude = abs(value)
    degrees = math.floor(magnitude)
    return sign * (degrees * 100.0 + (magnitude - degrees) * 60.0)
