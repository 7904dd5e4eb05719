"""The turret ICD's identifier table (sections 6 and 7), in-scope entries only.

Every entry carries the ICD section and the evidence for its numbers: each CAN id is
printed in decimal and hex in the ICD, and both were checked to agree (the test
`test_identifier_table_decimal_matches_hex` repeats the check on the printed pairs).
Conversions go from the device unit to the SI unit used on ROS interfaces.

Out of scope (weapon functions of sections 6.5-6.7 and the matching data of 7.1): not
listed here. The client treats every id that is not in this table as unknown and
ignores it, so frames carrying those functions are dropped without being decoded.

Reconstruction decisions:
* "UCAR" (Stop actuators 6.1.1, Yaw/Pitch current status 7.1.10/7.1.20) is read as
  UCHAR: the value is an 8-bit bit field and the other single-byte entries say UCHAR.
* Camera0 zoom position (7.5.1): the ICD's very last line (the file has no trailing
  newline, which an earlier reading dropped) gives `1342 (0x53E) Camera0 zoom position
  LONG count`: id 1342, LONG, raw counts (decimal and hex agree). The id stays
  configurable (`zoom_position_id`) for installations that moved it.
* Humidity is sent in % and is converted to a 0..1 fraction (sensor_msgs convention).
* Latitude/longitude stay in degrees (sensor_msgs/NavSatFix uses degrees).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum, IntEnum

from .datatypes import DataType

MASTER_NODE_ID = 100  # "All Examples of commands for master with Node-ID = 100 (0x64)"
TURRET_NODE_ID = 1
COVER_NODE_ID = 2
ROVER_GNSS_NODE_ID = 5
BASE_GNSS_NODE_ID = 6
ZOOM_NODE_ID = 7
DEFAULT_ZOOM_POSITION_ID = 1342  # ICD 7.5.1, last line

DEG = math.pi / 180.0


class Direction(Enum):
    COMMAND = "command"  # sent by the master
    DATA = "data"  # broadcast by a device node


@dataclass(frozen=True)
class Identifier:
    can_id: int
    key: str
    name: str
    direction: Direction
    data_type: DataType
    unit: str  # device unit as in the ICD
    si_unit: str
    si_scale: float  # SI value = device value * si_scale
    node_id: int | None  # transmitting node for data, None for commands
    section: str
    evidence: str
    used: bool = True  # False: the ICD marks it "(not use)"

    def to_si(self, value: float) -> float:
        return float(value) * self.si_scale

    def from_si(self, value: float) -> float:
        return float(value) / self.si_scale


def _cmd(can_id: int, key: str, name: str, data_type: DataType, unit: str, si_unit: str,
         scale: float, section: str, evidence: str, used: bool = True) -> Identifier:
    return Identifier(can_id, key, name, Direction.COMMAND, data_type, unit, si_unit, scale,
                      None, section, evidence, used)


def _data(can_id: int, key: str, name: str, data_type: DataType, unit: str, si_unit: str,
          scale: float, node_id: int, section: str, evidence: str,
          used: bool = True) -> Identifier:
    return Identifier(can_id, key, name, Direction.DATA, data_type, unit, si_unit, scale,
                      node_id, section, evidence, used)


_HEX = "decimal and hex agree"
_T = TURRET_NODE_ID

IDENTIFIERS: tuple[Identifier, ...] = (
    # 6.1 turret commands
    _cmd(300, "stop_actuators", "Stop actuators", DataType.UCHAR, "-", "-", 1.0, "6.1.1",
         f"300 (0x12C), {_HEX}; 'UCAR' read as UCHAR (bit 0 yaw, bit 1 pitch)"),
    _cmd(1300, "yaw_position_setpoint", "Yaw position set-point", DataType.FLOAT, "deg",
         "rad", DEG, "6.1.2", f"1300 (0x514), {_HEX}; example 20 deg = 41 A0 00 00"),
    _cmd(1301, "yaw_velocity_setpoint", "Yaw velocity set-point", DataType.FLOAT, "deg/s",
         "rad/s", DEG, "6.1.3", f"1301 (0x515), {_HEX}; example -10 deg/s = C1 20 00 00"),
    _cmd(1302, "yaw_relative_setpoint", "Yaw relative position set-point", DataType.FLOAT,
         "deg", "rad", DEG, "6.1.4", f"1302 (0x516), {_HEX}; example 90 deg = 42 B4 00 00"),
    _cmd(1307, "yaw_actuator_mode", "Yaw actuator mode", DataType.UCHAR, "-", "-", 1.0,
         "6.1.5", f"1307 (0x51B), {_HEX}; example auto brake = type 0x0A, value 2"),
    _cmd(1310, "pitch_position_setpoint", "Pitch position set-point", DataType.FLOAT, "deg",
         "rad", DEG, "6.1.1 (2nd, pitch)", f"1310 (0x51E), {_HEX}; yaw +10 pattern"),
    _cmd(1311, "pitch_velocity_setpoint", "Pitch velocity set-point", DataType.FLOAT,
         "deg/s", "rad/s", DEG, "6.1.2 (2nd, pitch)", f"1311 (0x51F), {_HEX}"),
    _cmd(1312, "pitch_relative_setpoint", "Pitch relative position set-point",
         DataType.FLOAT, "deg", "rad", DEG, "6.1.3 (2nd, pitch)", f"1312 (0x520), {_HEX}"),
    _cmd(1317, "pitch_actuator_mode", "Pitch actuator mode", DataType.UCHAR, "-", "-", 1.0,
         "6.1.4 (2nd, pitch)", f"1317 (0x525), {_HEX}"),
    _cmd(1420, "remember_position", "Remember current position", DataType.UCHAR, "-", "-",
         1.0, "6.1.5 (2nd)", f"1420 (0x58C), {_HEX}; value 1 = remember yaw and pitch"),
    _cmd(1421, "restore_position", "Set to saved position", DataType.UCHAR, "-", "-", 1.0,
         "6.1.6 (2nd)", f"1421 (0x58D), {_HEX}; value 1 = go to saved yaw and pitch"),
    # 6.2 camera commands (all marked "not use" in the ICD)
    _cmd(1340, "camera1_focus", "Camera1 focus control", DataType.CHAR, "-", "-", 1.0,
         "6.2.1", f"1340 (0x53C), {_HEX}; example rotate = type 0x09 value 1", used=False),
    _cmd(1341, "camera1_diaphragm", "Camera1 diaphragm control", DataType.CHAR, "-", "-",
         1.0, "6.2.2", f"1341 (0x53D), {_HEX}", used=False),
    _cmd(1350, "camera2_focus", "Camera2 focus control", DataType.CHAR, "-", "-", 1.0,
         "6.2.3", f"1350 (0x546), {_HEX}", used=False),
    _cmd(1351, "camera2_diaphragm", "Camera2 diaphragm control", DataType.CHAR, "-", "-",
         1.0, "6.2.4", f"1351 (0x547), {_HEX}", used=False),
    _cmd(1360, "camera3_focus", "Camera3 focus control", DataType.CHAR, "-", "-", 1.0,
         "6.2.5", f"1360 (0x550), {_HEX}", used=False),
    _cmd(1361, "camera3_diaphragm", "Camera3 diaphragm control", DataType.CHAR, "-", "-",
         1.0, "6.2.6", f"1361 (0x551), {_HEX}", used=False),
    _cmd(1370, "camera4_focus", "Camera4 focus control", DataType.CHAR, "-", "-", 1.0,
         "6.2.7", f"1370 (0x55A), {_HEX}", used=False),
    _cmd(1371, "camera4_diaphragm", "Camera4 diaphragm control", DataType.CHAR, "-", "-",
         1.0, "6.2.8", f"1371 (0x55B), {_HEX}", used=False),
    # 6.3, 6.4, 6.8, 6.9
    _cmd(1400, "cover_control", "Cover control", DataType.UCHAR, "-", "-", 1.0, "6.3.1",
         f"1400 (0x578), {_HEX}; example open = type 0x0A value 1; 0 close, 1 open"),
    _cmd(1403, "fan_control", "Fan control", DataType.UCHAR, "-", "-", 1.0, "6.4.1",
         f"1403 (0x57B), {_HEX}; 0 off, 1 on"),
    _cmd(1414, "charging_control", "Charging control", DataType.UCHAR, "-", "-", 1.0,
         "6.8.1", f"1414 (0x586), {_HEX}; 0 off, 1 on"),
    _cmd(1430, "oes_heater_control", "OES heater control", DataType.UCHAR, "-", "-", 1.0,
         "6.9.1", f"1430 (0x596), {_HEX}; 0 off, 1 on"),
    _cmd(1432, "drives_heater_control", "Drives heater control", DataType.UCHAR, "-", "-",
         1.0, "6.9.2", f"1432 (0x598), {_HEX}; 0 off, 1 on", used=False),
    # 7.1 turret data, node 1
    _data(1303, "yaw_position", "Yaw actual position", DataType.FLOAT, "deg", "rad", DEG, _T,
          "7.1.1", f"1303 (0x517), {_HEX}; range -180..180"),
    _data(1304, "yaw_velocity", "Yaw actual velocity", DataType.FLOAT, "deg/s", "rad/s", DEG,
          _T, "7.1.2", f"1304 (0x518), {_HEX}"),
    _data(1305, "yaw_motor_temperature", "Yaw motor temperature", DataType.FLOAT, "degC",
          "degC", 1.0, _T, "7.1.3", f"1305 (0x519), {_HEX}"),
    _data(1308, "yaw_actuator_mode_state", "Yaw current actuator mode", DataType.UCHAR, "-",
          "-", 1.0, _T, "7.1.4", f"1308 (0x51C), {_HEX}"),
    _data(1461, "yaw_bus_voltage", "Yaw current bus voltage", DataType.FLOAT, "V", "V", 1.0,
          _T, "7.1.5", f"1461 (0x5B5), {_HEX}"),
    _data(1462, "yaw_current", "Yaw actual current", DataType.FLOAT, "A", "A", 1.0, _T,
          "7.1.6", f"1462 (0x5B6), {_HEX}"),
    _data(1464, "yaw_humidity", "Yaw current humidity", DataType.FLOAT, "%", "fraction", 0.01,
          _T, "7.1.7", f"1464 (0x5B8), {_HEX}"),
    _data(1465, "yaw_power_stage_temperature", "Yaw power stage temperature", DataType.FLOAT,
          "degC", "degC", 1.0, _T, "7.1.8", f"1465 (0x5B9), {_HEX}"),
    _data(1466, "yaw_revolutions", "Yaw number of revolution", DataType.LONG, "-", "-", 1.0,
          _T, "7.1.9", f"1466 (0x5BA), {_HEX}"),
    _data(1467, "yaw_status", "Yaw current status", DataType.UCHAR, "-", "-", 1.0, _T,
          "7.1.10", f"1467 (0x5BB), {_HEX}; 'UCAR' read as UCHAR bit field"),
    _data(1313, "pitch_position", "Pitch actual position", DataType.FLOAT, "deg", "rad", DEG,
          _T, "7.1.11", f"1313 (0x521), {_HEX}; range -180..180"),
    _data(1314, "pitch_velocity", "Pitch actual velocity", DataType.FLOAT, "deg/s", "rad/s",
          DEG, _T, "7.1.12", f"1314 (0x522), {_HEX}"),
    _data(1315, "pitch_motor_temperature", "Pitch motor temperature", DataType.FLOAT, "degC",
          "degC", 1.0, _T, "7.1.13", f"1315 (0x523), {_HEX}"),
    _data(1318, "pitch_actuator_mode_state", "Pitch current actuator mode", DataType.UCHAR,
          "-", "-", 1.0, _T, "7.1.14", f"1318 (0x526), {_HEX}"),
    _data(1481, "pitch_bus_voltage", "Pitch current bus voltage", DataType.FLOAT, "V", "V",
          1.0, _T, "7.1.15", f"1481 (0x5C9), {_HEX}; yaw id + 20 pattern"),
    _data(1482, "pitch_current", "Pitch actual current", DataType.FLOAT, "A", "A", 1.0, _T,
          "7.1.16", f"1482 (0x5CA), {_HEX}"),
    _data(1484, "pitch_humidity", "Pitch current humidity", DataType.FLOAT, "%", "fraction",
          0.01, _T, "7.1.17", f"1484 (0x5CC), {_HEX}"),
    _data(1485, "pitch_power_stage_temperature", "Pitch power stage temperature",
          DataType.FLOAT, "degC", "degC", 1.0, _T, "7.1.18", f"1485 (0x5CD), {_HEX}"),
    _data(1486, "pitch_revolutions", "Pitch number of revolution", DataType.LONG, "-", "-",
          1.0, _T, "7.1.19", f"1486 (0x5CE), {_HEX}"),
    _data(1487, "pitch_status", "Pitch current status", DataType.UCHAR, "-", "-", 1.0, _T,
          "7.1.20", f"1487 (0x5CF), {_HEX}; same bit layout as yaw status"),
    _data(1404, "fan_state", "Fan state", DataType.UCHAR, "-", "-", 1.0, _T, "7.1.22",
          f"1404 (0x57C), {_HEX}; 0 disabled, 1 enabled ('Fun state' typo)"),
    _data(1405, "case_temperature", "Case temperature", DataType.FLOAT, "degC", "degC", 1.0,
          _T, "7.1.23", f"1405 (0x57D), {_HEX}"),
    _data(1413, "charging_current", "Charging current", DataType.FLOAT, "A", "A", 1.0, _T,
          "7.1.24", f"1413 (0x585), {_HEX}"),
    _data(1415, "charging_state", "Charging state", DataType.UCHAR, "-", "-", 1.0, _T,
          "7.1.25", f"1415 (0x587), {_HEX}"),
    _data(1431, "oes_heater_state", "OES heater state", DataType.UCHAR, "-", "-", 1.0, _T,
          "7.1.28", f"1431 (0x597), {_HEX}; bit 0 enabled, bit 1 current flows"),
    _data(1433, "drives_heater_state", "Drives heater state", DataType.UCHAR, "-", "-", 1.0,
          _T, "7.1.29", f"1433 (0x599), {_HEX}", used=False),
    _data(1435, "periphery_status", "Periphery status", DataType.ULONG, "-", "-", 1.0, _T,
          "7.1.30", f"1435 (0x59B), {_HEX}; bits 0..8 (bits 5-6 out of scope)"),
    _data(1801, "global_pitch", "Global pitch position (inclinometer)", DataType.FLOAT,
          "deg", "rad", DEG, _T, "7.1.31", f"1801 (0x709), {_HEX}; UDL channel"),
    _data(1802, "global_roll", "Global roll position (inclinometer)", DataType.FLOAT, "deg",
          "rad", DEG, _T, "7.1.32", f"1802 (0x70A), {_HEX}; UDL channel"),
    # 7.2 cover, node 2
    _data(1409, "cover_state", "Cover state", DataType.UCHAR, "-", "-", 1.0, COVER_NODE_ID,
          "7.2.1", f"1409 (0x581), {_HEX}; 0 closed, 1 opened, 2 middle; 100 ms default"),
    # 7.3 rover GNSS, node 5
    _data(1507, "rover_heading", "Current heading", DataType.LONG, "deg*1e-5", "rad",
          1e-5 * DEG, ROVER_GNSS_NODE_ID, "7.3.1", f"1507 (0x5E3), {_HEX}"),
    _data(1509, "rover_heading_accuracy", "Current accuracy", DataType.LONG, "deg*1e-5",
          "rad", 1e-5 * DEG, ROVER_GNSS_NODE_ID, "7.3.2", f"1509 (0x5E5), {_HEX}"),
    _data(1800, "global_yaw", "Global yaw position (heading)", DataType.FLOAT, "deg", "rad",
          DEG, ROVER_GNSS_NODE_ID, "7.3.3", f"1800 (0x708), {_HEX}; UDL channel"),
    # 7.4 base GNSS, node 6
    _data(1520, "latitude", "Latitude", DataType.LONG, "deg*1e-7", "deg", 1e-7,
          BASE_GNSS_NODE_ID, "7.4.1", f"1520 (0x5F0), {_HEX}"),
    _data(1521, "longitude", "Longitude", DataType.LONG, "deg*1e-7", "deg", 1e-7,
          BASE_GNSS_NODE_ID, "7.4.2", f"1521 (0x5F1), {_HEX}"),
    _data(1523, "altitude_msl", "Altitude mean sea level", DataType.LONG, "mm", "m", 1e-3,
          BASE_GNSS_NODE_ID, "7.4.3", f"1523 (0x5F3), {_HEX}"),
    _data(1524, "position_accuracy", "Position accuracy estimate", DataType.ULONG, "m*1e-4",
          "m", 1e-4, BASE_GNSS_NODE_ID, "7.4.4", f"1524 (0x5F4), {_HEX}"),
    _data(1528, "utc_time", "UTC time", DataType.ULONG, "s", "s", 1.0, BASE_GNSS_NODE_ID,
          "7.4.5", f"1528 (0x5F8), {_HEX}"),
    # 7.5 zoom, node 7 (the ICD's last line, see module notes)
    _data(DEFAULT_ZOOM_POSITION_ID, "zoom_position", "Camera0 zoom position", DataType.LONG,
          "count", "count", 1.0, ZOOM_NODE_ID, "7.5.1",
          f"1342 (0x53E), {_HEX}; last line of the ICD (no trailing newline)"),
)

BY_ID: dict[int, Identifier] = {ident.can_id: ident for ident in IDENTIFIERS}
BY_KEY: dict[str, Identifier] = {ident.key: ident for ident in IDENTIFIERS}
DATA_IDENTIFIERS = tuple(i for i in IDENTIFIERS if i.direction is Direction.DATA)
COMMAND_IDENTIFIERS = tuple(i for i in IDENTIFIERS if i.direction is Direction.COMMAND)


def identifier_table(zoom_position_id: int = DEFAULT_ZOOM_POSITION_ID) -> dict[int, Identifier]:
    """id -> Identifier, with the zoom position moved to the configured id."""
    table = dict(BY_ID)
    if zoom_position_id != DEFAULT_ZOOM_POSITION_ID:
        zoom = table.pop(DEFAULT_ZOOM_POSITION_ID)
        if zoom_position_id in table:
            raise ValueError(f"zoom position id {zoom_position_id} is already "
                             f"{table[zoom_position_id].key}")
        table[zoom_position_id] = Identifier(
            zoom_position_id, zoom.key, zoom.name, zoom.direction, zoom.data_type, zoom.unit,
            zoom.si_unit, zoom.si_scale, zoom.node_id, zoom.section, zoom.evidence)
    return table


# --- bit fields ------------------------------------------------------------------------

class ActuatorMode(IntEnum):
    """6.1.5 / 7.1.4: actuator mode values."""

    FREE_RUN = 0
    WITHOUT_BRAKE = 1
    AUTO_BRAKE = 2


class TargetState(IntEnum):
    """7.1.10 bits 0-1."""

    NOT_REACHED = 0
    REACHED = 1
    JOG = 2


class CoverState(IntEnum):
    CLOSED = 0
    OPENED = 1
    MIDDLE = 2


STOP_YAW_BIT = 0x01
STOP_PITCH_BIT = 0x02


@dataclass(frozen=True)
class AxisStatus:
    """Decoded yaw/pitch current status byte (7.1.10, 7.1.20)."""

    raw: int
    target: int  # TargetState value (3 = undefined)
    actuator_mode: int  # ActuatorMode value (3 = undefined)
    enabled: bool

    @classmethod
    def decode(cls, raw: int) -> AxisStatus:
        return cls(raw & 0xFF, raw & 0x03, (raw >> 2) & 0x03, bool(raw & 0x80))

    @staticmethod
    def encode(target: int, actuator_mode: int, enabled: bool) -> int:
        return (target & 0x03) | ((actuator_mode & 0x03) << 2) | (0x80 if enabled else 0)

    @property
    def target_name(self) -> str:
        try:
            return TargetState(self.target).name.lower()
        except ValueError:
            return f"undefined({self.target})"

    @property
    def mode_name(self) -> str:
        try:
            return ActuatorMode(self.actuator_mode).name.lower()
        except ValueError:
            return f"undefined({self.actuator_mode})"


@dataclass(frozen=True)
class PeripheryBit:
    bit: int
    key: str
    description: str
    fault: bool = False  # a set bit is a fault (WARN) rather than a state


# 7.1.30. Bits 5 and 6 belong to the out-of-scope functions and are not decoded;
# bits 9..31 are reserved.
PERIPHERY_BITS: tuple[PeripheryBit, ...] = (
    PeripheryBit(0, "fan_enabled", "fan enabled"),
    PeripheryBit(1, "oes_heater_enabled", "OES heater enabled"),
    PeripheryBit(2, "oes_heater_current", "OES heater current flows"),
    PeripheryBit(3, "drives_heater_enabled", "drives heater enabled"),
    PeripheryBit(4, "free_run_button_pressed", "free run button pressed"),
    PeripheryBit(7, "charging_enabled", "charging enabled"),
    PeripheryBit(8, "case_temperature_sensor_fault", "case temperature sensor fault",
                 fault=True),
)
PERIPHERY_DECODED_MASK = sum(1 << b.bit for b in PERIPHERY_BITS)


def decode_periphery(raw: int) -> dict[str, bool]:
    """Periphery status bits by key (only the in-scope, defined bits)."""
    return {bit.key: bool(raw >> bit.bit & 1) for bit in PERIPHERY_BITS}


OES_HEATER_ENABLED_BIT = 0x01
OES_HEATER_CURRENT_BIT = 0x02
