"""UCSP packet table (manual chapter 5.5): every category and packet, SI scaling.

Each packet class holds values in SI units (radians, rad/s, metres, m/s) or in
the unit a ROS message uses for the same quantity (latitude/longitude in degrees
as in sensor_msgs/NavSatFix, zoom as a 0..1 fraction). ``to_payload`` converts to
the device encoding and checks ranges *before* anything can be sent;
``from_payload`` checks the payload length and converts back.

Reconstruction notes (OCR text; decisions cross-checked inside the document):

====================  =======================================================
item                  decision
====================  =======================================================
Mode 2 "Safe Mode"    is STOW of 4.2 (tilt +90 deg, pan 0); named ``STOW``.
Mode 6 "Gull"         OCR of "Full Autoalign" (4.6 names Gyro / Full).
Report Zoom int16     Set Zoom says uint16; both carry 0..16383, so both fit;
                      decoded as int16 (as written) and range-checked.
Vel "Est"             East (North / East / Down triple).
Alt "meters * 1e5"    written identically in 5.5.5.2 and 5.5.5.3: kept
                      (int32 gives +-21474 m, enough for the vehicles of 1.0).
Vehicle rates         table rows say Yaw/Pitch/Roll, the text says p, q, r in
                      the body frame: the table order is followed, i.e.
                      position 0 = yaw rate (r), 1 = pitch rate (q),
                      2 = roll rate (p).
Request Frequency     its text says "request the gimbal version" (copy of
                      5.5.2.2); the packet id 0x04 and title are followed.
Report IR Palette     body missing from the text (page 21 lost): assumed to
                      mirror Set IR Palette (one uint16 colour scheme).
IR palette values     no table in the text: any uint16 is accepted.
Antenna position      int16 millimetres, so +-32.767 m.
Roll fields           "not implemented": always encoded as 0 and ignored.
====================  =======================================================

Sections 5.6 (periodic reports) and 5.7 (summary) are missing. The periodic set
is reconstructed from the packet descriptions: every GMB->CTRL packet that is not
the answer to a request (see ``PERIODIC_REPORTS``).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar

from .framing import Frame, ProtocolError, encode_frame

# --- categories (5.5) -------------------------------------------------------
CATEGORY_NV_MEMORY = 0x04
CATEGORY_DEVICE_INFO = 0x08
CATEGORY_GIMBAL = 0x09
CATEGORY_CAMERA = 0x0A
CATEGORY_EXTERNAL_FEED = 0x0B
CATEGORY_IR = 0x0C

CATEGORY_NAMES = {
    CATEGORY_NV_MEMORY: "Non Volatile Memory",
    CATEGORY_DEVICE_INFO: "Device Information",
    CATEGORY_GIMBAL: "Gimbal",
    CATEGORY_CAMERA: "Camera",
    CATEGORY_EXTERNAL_FEED: "External Feed",
    CATEGORY_IR: "IR Specific",
}

TO_GIMBAL = "CTRL->GMB"
FROM_GIMBAL = "GMB->CTRL"

ZOOM_MAX_RAW = 16383
TELEMETRY_RATE_MIN_HZ = 1
TELEMETRY_RATE_MAX_HZ = 200

_INT16 = (-(2**15), 2**15 - 1)
_UINT16 = (0, 2**16 - 1)
_INT32 = (-(2**31), 2**31 - 1)


class PayloadError(ProtocolError):
    """A payload has the wrong size for its packet."""


class RangeError(ProtocolError):
    """A value is outside what the packet (or the device) accepts."""


class UnknownPacketError(ProtocolError):
    """A checksum-valid frame whose category/id is not in chapter 5."""


class GimbalMode(IntEnum):
    """Set/Report Mode numbers (5.5.3.1)."""

    ANGLES = 0
    RATES = 1
    STOW = 2
    PILOT = 3
    INIT = 4
    GYRO_AUTOALIGN = 5
    FULL_AUTOALIGN = 6
    FFC_CALIBRATION = 7


MODE_NAMES: dict[str, GimbalMode] = {mode.name.lower(): mode for mode in GimbalMode}


def mode_name(mode: int) -> str:
    """Lower-case mode name, or ``unknown(<n>)`` for a number not in the table."""
    try:
        return GimbalMode(mode).name.lower()
    except ValueError:
        return f"unknown({mode})"


class GimbalType(IntEnum):
    """Report Gimbal Type values (5.5.4.3)."""

    UNDEFINED = 0
    IR = 1
    DAYLIGHT = 2


class GpsFeed(IntEnum):
    """Configure GPS Feed values (5.5.5.4)."""

    INTERNAL = 0
    EXTERNAL = 1


def _to_raw(name: str, value: float, scale: float, limits: tuple[int, int], unit: str) -> int:
    """Scale an SI value to a device integer, refusing NaN and out-of-range values."""
    if not isinstance(value, int | float) or math.isnan(value) or math.isinf(value):
        raise RangeError(f"{name} must be a finite number, got {value!r}")
    raw = round(value * scale)
    if not limits[0] <= raw <= limits[1]:
        raise RangeError(
            f"{name} {value:g} {unit} is outside the accepted range "
            f"[{limits[0] / scale:g}, {limits[1] / scale:g}] {unit}"
        )
    return raw


def _check(name: str, value: float, low: float, high: float, unit: str) -> None:
    if not isinstance(value, int | float) or math.isnan(value) or not low <= value <= high:
        raise RangeError(f"{name} {value!r} {unit} is outside [{low:g}, {high:g}] {unit}")


_DEG100_PER_RAD = 100.0 * 180.0 / math.pi  # deg*100 units per radian
_DEG1E4_PER_RAD = 1e4 * 180.0 / math.pi


class Packet:
    """Base of every UCSP packet: identity, direction and payload codec."""

    CATEGORY: ClassVar[int]
    PACKET_ID: ClassVar[int]
    DIRECTION: ClassVar[str]
    FORMAT: ClassVar[str] = "<"
    TITLE: ClassVar[str]

    @classmethod
    def payload_length(cls) -> int:
        return struct.calcsize(cls.FORMAT)

    def raw_fields(self) -> tuple[int, ...]:
        """Device integers in payload order (after range checks)."""
        return ()

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> Packet:
        return cls()

    def to_payload(self) -> bytes:
        return struct.pack(self.FORMAT, *self.raw_fields())

    @classmethod
    def from_payload(cls, payload: bytes) -> Packet:
        expected = cls.payload_length()
        if len(payload) != expected:
            raise PayloadError(
                f"{cls.TITLE} (cat 0x{cls.CATEGORY:02X} id 0x{cls.PACKET_ID:02X}) needs "
                f"{expected} payload bytes, got {len(payload)}"
            )
        return cls.from_raw(struct.unpack(cls.FORMAT, payload))

    def encode(self) -> bytes:
        """Complete wire packet (range-checked)."""
        return encode_frame(self.CATEGORY, self.PACKET_ID, self.to_payload())


class _EmptyPacket(Packet):
    FORMAT = "<"


# --- 5.5.1 Non volatile memory ---------------------------------------------
@dataclass(frozen=True)
class SaveConfiguration(_EmptyPacket):
    """Write the current configuration to NV memory (gimbal silent ~1 s)."""

    CATEGORY = CATEGORY_NV_MEMORY
    PACKET_ID = 0x01
    DIRECTION = TO_GIMBAL
    TITLE = "Save Configuration"


@dataclass(frozen=True)
class SaveFfc(_EmptyPacket):
    """Write the FFC calibration to the IR module NV memory (up to 10 s)."""

    CATEGORY = CATEGORY_NV_MEMORY
    PACKET_ID = 0x02
    DIRECTION = TO_GIMBAL
    TITLE = "Save FFC"


# --- 5.5.2 Device information ----------------------------------------------
@dataclass(frozen=True)
class VersionReport(Packet):
    """Serial numbers and firmware versions (answer to VersionRequest)."""

    CATEGORY = CATEGORY_DEVICE_INFO
    PACKET_ID = 0x01
    DIRECTION = FROM_GIMBAL
    FORMAT = "<hhiih"
    TITLE = "Report Gimbal Version"

    mb_serial: int = 0
    sb_serial: int = 0
    cpu0_version: int = 0
    cpu1_version: int = 0
    nv_version: int = 0

    def raw_fields(self) -> tuple[int, ...]:
        fields = (self.mb_serial, self.sb_serial, self.cpu0_version, self.cpu1_version,
                  self.nv_version)
        limits = (_INT16, _INT16, _INT32, _INT32, _INT16)
        names = ("mb_serial", "sb_serial", "cpu0_version", "cpu1_version", "nv_version")
        for name, value, (low, high) in zip(names, fields, limits, strict=True):
            _check(name, value, low, high, "")
        return fields

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> VersionReport:
        return cls(*fields)

    @property
    def serial_number(self) -> str:
        """Main board / sensor board serial numbers as one hardware id."""
        return f"{self.mb_serial}-{self.sb_serial}"

    @property
    def firmware(self) -> str:
        return f"cpu0 {self.cpu0_version} cpu1 {self.cpu1_version} nv {self.nv_version}"


@dataclass(frozen=True)
class VersionRequest(_EmptyPacket):
    CATEGORY = CATEGORY_DEVICE_INFO
    PACKET_ID = 0x02
    DIRECTION = TO_GIMBAL
    TITLE = "Request Gimbal Version"


@dataclass(frozen=True)
class TelemetryRateReport(Packet):
    """Rate of each periodic report, Hz."""

    CATEGORY = CATEGORY_DEVICE_INFO
    PACKET_ID = 0x03
    DIRECTION = FROM_GIMBAL
    FORMAT = "<H"
    TITLE = "Report Telemetry Data Frequency"

    rate_hz: int = 0

    def raw_fields(self) -> tuple[int, ...]:
        _check("telemetry rate", self.rate_hz, *_UINT16, "Hz")
        return (int(self.rate_hz),)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> TelemetryRateReport:
        return cls(fields[0])


@dataclass(frozen=True)
class TelemetryRateRequest(_EmptyPacket):
    CATEGORY = CATEGORY_DEVICE_INFO
    PACKET_ID = 0x04
    DIRECTION = TO_GIMBAL
    TITLE = "Request Telemetry Data Frequency"


@dataclass(frozen=True)
class SetTelemetryRate(Packet):
    """Set the periodic report rate, 1..200 Hz (5.5.2.5)."""

    CATEGORY = CATEGORY_DEVICE_INFO
    PACKET_ID = 0x05
    DIRECTION = TO_GIMBAL
    FORMAT = "<H"
    TITLE = "Set Telemetry Data Frequency"

    rate_hz: int = 50

    def raw_fields(self) -> tuple[int, ...]:
        if not float(self.rate_hz).is_integer():  # a caller may pass a float
            raise RangeError(f"telemetry rate must be a whole number of Hz, got {self.rate_hz}")
        _check("telemetry rate", self.rate_hz, TELEMETRY_RATE_MIN_HZ, TELEMETRY_RATE_MAX_HZ, "Hz")
        return (int(self.rate_hz),)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> SetTelemetryRate:
        return cls(fields[0])


# --- 5.5.3 Gimbal -----------------------------------------------------------
@dataclass(frozen=True)
class SetMode(Packet):
    CATEGORY = CATEGORY_GIMBAL
    PACKET_ID = 0x01
    DIRECTION = TO_GIMBAL
    FORMAT = "<h"
    TITLE = "Set Mode"

    mode: int = GimbalMode.ANGLES

    def raw_fields(self) -> tuple[int, ...]:
        if self.mode not in set(GimbalMode):
            raise RangeError(
                f"mode {self.mode!r} is not a U-Camera mode; known: "
                + ", ".join(f"{m.value}={m.name.lower()}" for m in GimbalMode)
            )
        return (int(self.mode),)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> SetMode:
        return cls(fields[0])


@dataclass(frozen=True)
class ModeReport(Packet):
    """Current mode (periodic). Unknown numbers are kept, see ``mode_name``."""

    CATEGORY = CATEGORY_GIMBAL
    PACKET_ID = 0x02
    DIRECTION = FROM_GIMBAL
    FORMAT = "<h"
    TITLE = "Report Mode"

    mode: int = GimbalMode.ANGLES

    def raw_fields(self) -> tuple[int, ...]:
        _check("mode", self.mode, *_INT16, "")
        return (int(self.mode),)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> ModeReport:
        try:
            return cls(GimbalMode(fields[0]))
        except ValueError:
            return cls(fields[0])


@dataclass(frozen=True)
class _PanTilt(Packet):
    """Pan/tilt pair in deg*100 (or deg/s*100) on the wire, radians here."""

    FORMAT = "<hhh"
    UNIT: ClassVar[str] = "rad"

    pan: float = 0.0
    tilt: float = 0.0

    def raw_fields(self) -> tuple[int, ...]:
        pan = _to_raw("pan", self.pan, _DEG100_PER_RAD, _INT16, self.UNIT)
        tilt = _to_raw("tilt", self.tilt, _DEG100_PER_RAD, _INT16, self.UNIT)
        return (pan, tilt, 0)  # roll: "not implemented, fill with zero"

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> _PanTilt:
        return cls(fields[0] / _DEG100_PER_RAD, fields[1] / _DEG100_PER_RAD)


@dataclass(frozen=True)
class SetRates(_PanTilt):
    """Pan/tilt rates in rad/s; effective in RATES mode only."""

    CATEGORY = CATEGORY_GIMBAL
    PACKET_ID = 0x03
    DIRECTION = TO_GIMBAL
    TITLE = "Set Gimbal Rates"
    UNIT = "rad/s"


@dataclass(frozen=True)
class RatesReport(_PanTilt):
    CATEGORY = CATEGORY_GIMBAL
    PACKET_ID = 0x04
    DIRECTION = FROM_GIMBAL
    TITLE = "Report Gimbal Rates"
    UNIT = "rad/s"


@dataclass(frozen=True)
class SetAngles(_PanTilt):
    """Pan/tilt angles in rad; effective in ANGLES mode only."""

    CATEGORY = CATEGORY_GIMBAL
    PACKET_ID = 0x05
    DIRECTION = TO_GIMBAL
    TITLE = "Set Gimbal Angles"


@dataclass(frozen=True)
class AnglesReport(_PanTilt):
    CATEGORY = CATEGORY_GIMBAL
    PACKET_ID = 0x06
    DIRECTION = FROM_GIMBAL
    TITLE = "Report Gimbal Angles"


# --- 5.5.4 Camera -----------------------------------------------------------
@dataclass(frozen=True)
class SetZoom(Packet):
    """Optical zoom as a fraction: 0 = wide (raw 0), 1 = tele (raw 16383)."""

    CATEGORY = CATEGORY_CAMERA
    PACKET_ID = 0x01
    DIRECTION = TO_GIMBAL
    FORMAT = "<H"
    TITLE = "Set Camera Zoom"

    level: float = 0.0

    def raw_fields(self) -> tuple[int, ...]:
        return (_to_raw("zoom", self.level, ZOOM_MAX_RAW, (0, ZOOM_MAX_RAW), "(fraction)"),)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> SetZoom:
        if not 0 <= fields[0] <= ZOOM_MAX_RAW:
            raise RangeError(f"zoom value {fields[0]} is outside 0..{ZOOM_MAX_RAW}")
        return cls(fields[0] / ZOOM_MAX_RAW)


@dataclass(frozen=True)
class ZoomReport(Packet):
    CATEGORY = CATEGORY_CAMERA
    PACKET_ID = 0x02
    DIRECTION = FROM_GIMBAL
    FORMAT = "<h"
    TITLE = "Report Camera Zoom"

    level: float = 0.0

    def raw_fields(self) -> tuple[int, ...]:
        return (_to_raw("zoom", self.level, ZOOM_MAX_RAW, (0, ZOOM_MAX_RAW), "(fraction)"),)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> ZoomReport:
        if not 0 <= fields[0] <= ZOOM_MAX_RAW:
            raise RangeError(f"reported zoom {fields[0]} is outside 0..{ZOOM_MAX_RAW}")
        return cls(fields[0] / ZOOM_MAX_RAW)


@dataclass(frozen=True)
class GimbalTypeReport(Packet):
    CATEGORY = CATEGORY_CAMERA
    PACKET_ID = 0x03
    DIRECTION = FROM_GIMBAL
    FORMAT = "<h"
    TITLE = "Report Gimbal Type"

    gimbal_type: int = GimbalType.UNDEFINED

    def raw_fields(self) -> tuple[int, ...]:
        _check("gimbal type", self.gimbal_type, *_INT16, "")
        return (int(self.gimbal_type),)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> GimbalTypeReport:
        try:
            return cls(GimbalType(fields[0]))
        except ValueError:
            return cls(fields[0])


# --- 5.5.5 External feed ----------------------------------------------------
@dataclass(frozen=True)
class _NedVelocity(Packet):
    """North/East/Down velocity in m/s (device: int32 m/s * 100)."""

    FORMAT = "<iii"

    north: float = 0.0
    east: float = 0.0
    down: float = 0.0

    def raw_fields(self) -> tuple[int, ...]:
        return tuple(
            _to_raw(f"velocity {name}", value, 1e2, _INT32, "m/s")
            for name, value in (("north", self.north), ("east", self.east), ("down", self.down))
        )

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> _NedVelocity:
        return cls(*(value / 1e2 for value in fields))


@dataclass(frozen=True)
class GpsVelocities(_NedVelocity):
    CATEGORY = CATEGORY_EXTERNAL_FEED
    PACKET_ID = 0x01
    DIRECTION = TO_GIMBAL
    TITLE = "Send GPS Velocities"


def _position_raw(latitude: float, longitude: float, altitude: float) -> tuple[int, int, int]:
    _check("latitude", latitude, -90.0, 90.0, "deg")
    _check("longitude", longitude, -180.0, 180.0, "deg")
    return (
        _to_raw("latitude", latitude, 1e7, _INT32, "deg"),
        _to_raw("longitude", longitude, 1e7, _INT32, "deg"),
        _to_raw("altitude", altitude, 1e5, _INT32, "m"),
    )


@dataclass(frozen=True)
class GpsPositionVelocities(Packet):
    """External GPS fix: latitude/longitude in degrees, altitude m, NED velocity m/s."""

    CATEGORY = CATEGORY_EXTERNAL_FEED
    PACKET_ID = 0x02
    DIRECTION = TO_GIMBAL
    FORMAT = "<iiiiii"
    TITLE = "Send GPS Position and Velocities"

    latitude: float = 0.0
    longitude: float = 0.0
    altitude: float = 0.0
    north: float = 0.0
    east: float = 0.0
    down: float = 0.0

    def raw_fields(self) -> tuple[int, ...]:
        velocity = GpsVelocities(self.north, self.east, self.down).raw_fields()
        return _position_raw(self.latitude, self.longitude, self.altitude) + velocity

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> GpsPositionVelocities:
        return cls(fields[0] / 1e7, fields[1] / 1e7, fields[2] / 1e5,
                   fields[3] / 1e2, fields[4] / 1e2, fields[5] / 1e2)


@dataclass(frozen=True)
class SystemPositionReport(Packet):
    """Position the gimbal computed (periodic): degrees, degrees, metres."""

    CATEGORY = CATEGORY_EXTERNAL_FEED
    PACKET_ID = 0x03
    DIRECTION = FROM_GIMBAL
    FORMAT = "<iii"
    TITLE = "System Position Report"

    latitude: float = 0.0
    longitude: float = 0.0
    altitude: float = 0.0

    def raw_fields(self) -> tuple[int, ...]:
        return _position_raw(self.latitude, self.longitude, self.altitude)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> SystemPositionReport:
        return cls(fields[0] / 1e7, fields[1] / 1e7, fields[2] / 1e5)


@dataclass(frozen=True)
class ConfigureGpsFeed(Packet):
    CATEGORY = CATEGORY_EXTERNAL_FEED
    PACKET_ID = 0x04
    DIRECTION = TO_GIMBAL
    FORMAT = "<B"
    TITLE = "Configure GPS Feed"

    source: int = GpsFeed.INTERNAL

    def raw_fields(self) -> tuple[int, ...]:
        if self.source not in set(GpsFeed):
            raise RangeError(f"GPS feed {self.source!r} must be 0 (internal) or 1 (external)")
        return (int(self.source),)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> ConfigureGpsFeed:
        if fields[0] not in set(GpsFeed):
            raise RangeError(f"GPS feed value {fields[0]} is neither 0 nor 1")
        return cls(GpsFeed(fields[0]))


@dataclass(frozen=True)
class VehicleAngles(Packet):
    """Vehicle Euler angles in rad (device: int32 deg * 1e4, order yaw, pitch, roll)."""

    CATEGORY = CATEGORY_EXTERNAL_FEED
    PACKET_ID = 0x05
    DIRECTION = TO_GIMBAL
    FORMAT = "<iii"
    TITLE = "Send Vehicle Angles"

    yaw: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0

    def raw_fields(self) -> tuple[int, ...]:
        _check("yaw", self.yaw, -2 * math.pi, 2 * math.pi, "rad")
        _check("pitch", self.pitch, -math.pi / 2, math.pi / 2, "rad")
        _check("roll", self.roll, -math.pi, math.pi, "rad")
        return tuple(
            _to_raw(name, value, _DEG1E4_PER_RAD, _INT32, "rad")
            for name, value in (("yaw", self.yaw), ("pitch", self.pitch), ("roll", self.roll))
        )

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> VehicleAngles:
        return cls(*(value / _DEG1E4_PER_RAD for value in fields))


@dataclass(frozen=True)
class VehicleAngularVelocities(Packet):
    """Body rates in rad/s, wire order yaw rate (r), pitch rate (q), roll rate (p)."""

    CATEGORY = CATEGORY_EXTERNAL_FEED
    PACKET_ID = 0x06
    DIRECTION = TO_GIMBAL
    FORMAT = "<iii"
    TITLE = "Send Vehicle Angular Velocities"

    yaw_rate: float = 0.0
    pitch_rate: float = 0.0
    roll_rate: float = 0.0

    def raw_fields(self) -> tuple[int, ...]:
        return tuple(
            _to_raw(name, value, _DEG1E4_PER_RAD, _INT32, "rad/s")
            for name, value in (("yaw rate", self.yaw_rate), ("pitch rate", self.pitch_rate),
                                ("roll rate", self.roll_rate))
        )

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> VehicleAngularVelocities:
        return cls(*(value / _DEG1E4_PER_RAD for value in fields))


@dataclass(frozen=True)
class _AntennaPosition(Packet):
    """GPS antenna offset in the gimbal fixed frame, metres (device: int16 mm)."""

    FORMAT = "<hhh"

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0

    def raw_fields(self) -> tuple[int, ...]:
        return tuple(
            _to_raw(f"antenna {name}", value, 1e3, _INT16, "m")
            for name, value in (("x", self.x), ("y", self.y), ("z", self.z))
        )

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> _AntennaPosition:
        return cls(*(value / 1e3 for value in fields))


@dataclass(frozen=True)
class SetAntennaPosition(_AntennaPosition):
    CATEGORY = CATEGORY_EXTERNAL_FEED
    PACKET_ID = 0x07
    DIRECTION = TO_GIMBAL
    TITLE = "Set GPS Antenna Position"


@dataclass(frozen=True)
class AntennaPositionRequest(_EmptyPacket):
    CATEGORY = CATEGORY_EXTERNAL_FEED
    PACKET_ID = 0x08
    DIRECTION = TO_GIMBAL
    TITLE = "Request GPS Antenna Position"


@dataclass(frozen=True)
class AntennaPositionReport(_AntennaPosition):
    CATEGORY = CATEGORY_EXTERNAL_FEED
    PACKET_ID = 0x09
    DIRECTION = FROM_GIMBAL
    TITLE = "GPS Antenna Position Report"


# --- 5.5.6 IR specific ------------------------------------------------------
@dataclass(frozen=True)
class SetIrPalette(Packet):
    CATEGORY = CATEGORY_IR
    PACKET_ID = 0x01
    DIRECTION = TO_GIMBAL
    FORMAT = "<H"
    TITLE = "Set IR Palette"

    palette: int = 0

    def raw_fields(self) -> tuple[int, ...]:
        if not float(self.palette).is_integer():  # a caller may pass a float
            raise RangeError(f"IR palette must be a whole number, got {self.palette}")
        _check("IR palette", self.palette, *_UINT16, "")
        return (int(self.palette),)

    @classmethod
    def from_raw(cls, fields: tuple[int, ...]) -> SetIrPalette:
        return cls(fields[0])


@dataclass(frozen=True)
class IrPaletteReport(SetIrPalette):
    CATEGORY = CATEGORY_IR
    PACKET_ID = 0x02
    DIRECTION = FROM_GIMBAL
    TITLE = "Report IR Palette"


# --- tables -----------------------------------------------------------------
ALL_PACKETS: tuple[type[Packet], ...] = (
    SaveConfiguration, SaveFfc,
    VersionReport, VersionRequest, TelemetryRateReport, TelemetryRateRequest, SetTelemetryRate,
    SetMode, ModeReport, SetRates, RatesReport, SetAngles, AnglesReport,
    SetZoom, ZoomReport, GimbalTypeReport,
    GpsVelocities, GpsPositionVelocities, SystemPositionReport, ConfigureGpsFeed,
    VehicleAngles, VehicleAngularVelocities, SetAntennaPosition, AntennaPositionRequest,
    AntennaPositionReport,
    SetIrPalette, IrPaletteReport,
)

PACKET_TYPES: dict[tuple[int, int], type[Packet]] = {
    (cls.CATEGORY, cls.PACKET_ID): cls for cls in ALL_PACKETS
}

#: Reconstructed 5.6: sent by the gimbal at the telemetry rate, in this order.
#: IrPaletteReport is sent only by IR gimbals.
PERIODIC_REPORTS: tuple[type[Packet], ...] = (
    ModeReport, AnglesReport, RatesReport, ZoomReport, GimbalTypeReport, SystemPositionReport,
    IrPaletteReport,
)

#: Request -> answer pairs (the gimbal answers before its next periodic report).
REQUEST_ANSWERS: dict[type[Packet], type[Packet]] = {
    VersionRequest: VersionReport,
    TelemetryRateRequest: TelemetryRateReport,
    AntennaPositionRequest: AntennaPositionReport,
}


def expected_payload_length(category: int, packet_id: int) -> int | None:
    """Payload length of a known packet, None for unknown ones (for FrameParser)."""
    cls = PACKET_TYPES.get((category, packet_id))
    return None if cls is None else cls.payload_length()


def decode_packet(frame: Frame) -> Packet:
    """Turn a checksum-valid frame into its packet object.

    Raises UnknownPacketError for a category/id outside chapter 5, PayloadError
    for a wrong payload size and RangeError for a value the packet cannot carry.
    """
    cls = PACKET_TYPES.get(frame.key)
    if cls is None:
        raise UnknownPacketError(
            f"unknown packet category 0x{frame.category:02X} id 0x{frame.packet_id:02X} "
            f"({len(frame.payload)} payload bytes)"
        )
    return cls.from_payload(frame.payload)
