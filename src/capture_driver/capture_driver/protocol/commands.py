"""The reconstructed Capture command table (spec chapter 4), with the evidence for each opcode.

The OCR of the specification garbled most per-command opcode lines ("Dx010", "0x( A",
"Dx04.0"). Every opcode below was established from one or more of:

* **text**   an opcode printed legibly in the command's own section;
* **rev**    the revision history (front matter), which lists added/removed commands
  with their opcodes;
* **table**  the error-string table of section 4.10.22 or the data-format notes of 5.1;
* **example** a byte example in section 2 or chapter 7 whose checksum adds up;
* **order**  the position of the command inside its group: commands of a group are
  numbered consecutively in section order, so a command whose only free slot lies
  between two established neighbours gets that slot;
* **witness** the opcode table of a public third-party Cap-Track Wireshark dissector
  (and the tools built from it), a second witness for what the OCR lost. It agrees with
  81 of the 82 opcodes the document prints legibly; its facts (opcode, name) are used,
  never its encodings.

Confidence: ``high`` = printed legibly (text/rev/table/example), the single free slot
between two established neighbours, or a document fragment/order the witness confirms;
``medium`` = one source only (the witness where the document prints nothing, or section
order with both ends of the run established); ``low`` = section order with no witness
(GPS_GetLatitude): the node treats such polls as optional. Commands whose
opcode could not be established are **not** in :data:`COMMANDS`; they are listed in
:data:`UNRESOLVED` with the reason, and the encoder refuses them.

Weapon-station commands (the weapon-control-unit group and the weapon-related dual-gimbal
commands) are out of scope and deliberately absent; frames carrying their opcodes are
treated as unknown. Units are the device's (degrees, deg/s, mA, ms); the ROS node converts.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Any

from .datatypes import DataType, decode_value, encode_value
from .framing import Frame, ProtocolError


class UnknownCommand(ProtocolError):
    """The name is not an encodable command of the table."""


@dataclass(frozen=True)
class AxisRule:
    """What the axis byte means for a command and which values it accepts.

    ``allowed`` narrows ``low..high`` to a set (dual-gimbal axes 1, 2, 4, 5);
    ``in_group_byte`` means the number travels in the group byte and the axis byte is 0
    (the video tracker's camera index, 4.11).
    """

    name: str
    low: int
    high: int
    meaning: str
    allowed: tuple[int, ...] | None = None
    in_group_byte: bool = False

    def check(self, axis: int | None, command: str) -> int:
        if axis is None:
            if self.low == self.high:
                return self.low
            raise ProtocolError(f'{command} needs {self.meaning} ({self._choices()})')
        if isinstance(axis, bool) or not isinstance(axis, int):
            raise ProtocolError(f'{command}: {self.meaning} must be an integer, got {axis!r}')
        if not self.low <= axis <= self.high or (self.allowed and axis not in self.allowed):
            raise ProtocolError(
                f'{command}: {self.meaning} {axis} is outside {self._choices()}'
            )
        return axis

    def _choices(self) -> str:
        if self.allowed:
            return ', '.join(str(v) for v in self.allowed)
        return f'{self.low}..{self.high}'


MOTOR = AxisRule('motor', 1, 3, 'motor axis (1 yaw/pan, 2 pitch/tilt, 3 roll)')
SYSTEM = AxisRule('none', 0, 0, 'axis byte (ignored, sent as 0)')
TARGET = AxisRule('target', 1, 15, 'GPS target number in the axis byte')
PRESET = AxisRule('preset', 1, 15, 'preset number in the axis byte')
DIGITAL_IO = AxisRule('digital_io', 1, 6, 'digital I/O number in the axis byte')
IMU_SENSOR = AxisRule('imu_sensor', 0, 3, 'IMU sensor (0 client, 1 base, 2 load, 3 middle)')
IMU_AXIS = AxisRule('imu_axis', 1, 3, 'IMU axis (1 yaw, 2 pitch, 3 roll)')
CENTRAL_AXIS = AxisRule('central_axis', 0, 2, 'sensor axis (0 x, 1 y, 2 z)')
COMPENSATION = AxisRule('compensation', 2, 3, 'compensation (2 tilt, 3 roll)')
MEASUREMENT = AxisRule('measurement', 1, 5, 'LRF measurement (target) number')
CAMERA = AxisRule('camera', 0, 3, 'camera index (sent in the group byte, 4.11)',
                  in_group_byte=True)
PAN = AxisRule('pan', 1, 1, 'axis byte (pan axis only, 1)')
PELCO_AXIS = AxisRule('pelco_axis', 1, 2, 'Pelco-D axis (1 pan, 2 tilt)')
DG_PAIR = AxisRule('dg_pair', 1, 2, 'axis pair (1 pan/pan 2, 2 tilt/tilt 2)')
DG_AXIS = AxisRule('dg_axis', 1, 5, 'dual-gimbal axis (1 pan, 2 tilt, 4 pan 2, 5 tilt 2)',
                   allowed=(1, 2, 4, 5))
DG_GIMBAL2 = AxisRule('dg_gimbal2', 4, 5, 'gimbal 2 axis (4 pan 2, 5 tilt 2)')

AXIS_RULES = {
    rule.name: rule
    for rule in (MOTOR, SYSTEM, TARGET, PRESET, DIGITAL_IO, IMU_SENSOR, IMU_AXIS,
                 CENTRAL_AXIS, COMPENSATION, MEASUREMENT, CAMERA, PAN, PELCO_AXIS, DG_PAIR,
                 DG_AXIS, DG_GIMBAL2)
}


class Safety(Enum):
    """Why a command needs care; the node gates the last three behind opt-in parameters."""

    NONE = 'none'
    MOTION = 'motion'  # starts axis motion (the node has dedicated, limit-checked interfaces)
    NV_WRITE = 'nv_write'  # writes controller non-volatile memory
    REBOOT = 'reboot'  # reboots the controller or resets an axis
    NETWORK = 'network'  # changes IP/port/communication settings


@dataclass(frozen=True)
class Command:
    """One encodable command: opcode, axis rule, argument and reply types with units."""

    name: str
    opcode: int
    axis: AxisRule
    arg: DataType
    ret: DataType
    arg_unit: str
    ret_unit: str
    confidence: str
    evidence: str
    safety: Safety = Safety.NONE
    summary: str = ''

    @property
    def replies_with_data(self) -> bool:
        """Getters answer with a data packet; everything else with an ACK byte (2.1)."""
        return self.ret is not DataType.NONE

    def frame(self, axis: int | None = None, value: Any = None, group: int = 0) -> Frame:
        """Request packet; raises :class:`ProtocolError` naming the bad input."""
        axis_byte = self.axis.check(axis, self.name)
        payload = encode_value(self.arg, value, f'{self.name} argument')
        if not 0 <= group <= 0xFF:
            raise ProtocolError(f'{self.name}: group id {group} is outside 0..255')
        if self.axis.in_group_byte:  # camera index in the group byte, axis byte 0 (4.11)
            return Frame(axis_byte, 0, self.opcode, payload)
        return Frame(group, axis_byte, self.opcode, payload)

    def encode(self, axis: int | None = None, value: Any = None, group: int = 0) -> bytes:
        """Request packet bytes; raises :class:`ProtocolError` naming the bad input."""
        return self.frame(axis, value, group).encode()

    def decode_reply(self, frame: Frame) -> Any:
        if frame.opcode != self.opcode:
            raise ProtocolError(
                f'{self.name}: reply opcode 0x{frame.opcode:04X} != 0x{self.opcode:04X}'
            )
        return decode_value(self.ret, frame.data, f'{self.name} reply')

    def decode_request(self, frame: Frame) -> Any:
        """Argument carried by a request packet (used by the simulator)."""
        return decode_value(self.arg, frame.data, f'{self.name} argument')


N, U8, BOOL, U16, U32, F32, F64 = (
    DataType.NONE, DataType.U8, DataType.BOOL, DataType.U16, DataType.U32, DataType.F32,
    DataType.F64,
)
ASCII, IPV4, LLA, PRESET_FMT = DataType.ASCII, DataType.IPV4, DataType.LLA, DataType.PRESET
TARGETS = DataType.TARGETS

_ORDER_MOT = (
    'order: 4.2.11-4.2.15 fill 0x013C.. after MOT_SetPositionMode 0x013B (7.1 example) '
    'toward MOT_MotionComplete 0x0144 (4.2.19 text); 4.2.15 fragment "Dx014" agrees'
)
_ERR_TABLE = 'table: 4.10.22 error-message table'
_ORDER_PELCO = 'order: 4.13 section order, one opcode per command from 0x0C80'
# Second witness: a public Wireshark Lua dissector for the Cap-Track protocol and the C#
# and Python tools built from its opcode table. It agrees with 81 of the 82 opcodes the
# document prints legibly (the 82nd is a duplicate-key typo in the dissector:
# IP_GetControllerSubnetMask listed at 0x070B, SetControllerPort's opcode; 4.7.6 prints
# 0x071B). Only its opcode/name facts are used; encodings come from the document.
_WITNESS = 'witness: CapTrack dissector table'
_AGREE = '; ' + _WITNESS + ' agrees'

# (name, opcode, axis, arg, arg_unit, ret, ret_unit, confidence, evidence, safety, summary)
_TABLE: list[tuple[Any, ...]] = [
    # --- MOT get data (4.1) ------------------------------------------------------------
    ('MOT_MerRegister', 0x0101, MOTOR, N, '', U16, 'bits', 'high',
     'text: 4.10.1 "OpCode - 0x0101" (4.1.1 prints "Dx010")', Safety.NONE,
     'Motion Error Register'),
    ('MOT_DerRegister', 0x0102, MOTOR, N, '', U16, 'bits', 'high',
     'text: 4.10.2 "OpCode - 0x0102"', Safety.NONE, 'Detailed Error Register'),
    ('MOT_SrhRegister', 0x0103, MOTOR, N, '', U16, 'bits', 'high',
     'text: 4.10.3 "OpCode - 0x0103"', Safety.NONE, 'Status Register High'),
    ('MOT_SrlRegister', 0x0104, MOTOR, N, '', U16, 'bits', 'high',
     'text: 4.10.4 "OpCode - 0x0104"', Safety.NONE, 'Status Register Low'),
    ('MOT_MsrRegister', 0x0105, MOTOR, N, '', U16, 'bits', 'high',
     'text: 4.10.5 "OpCode - 0x0105"; 4.1.5 heading lost, named from "Motion Status Register"',
     Safety.NONE, 'Motion Status Register'),
    ('MOT_GetMotorCurrent', 0x0106, MOTOR, N, '', F32, 'mA', 'high',
     'order: only free slot between 0x0105 (4.10.5) and 0x0107 (2.1 example)', Safety.NONE,
     'actual motor current'),
    ('MOT_GetMotorVoltage', 0x0107, MOTOR, N, '', F32, 'V', 'high',
     'example: 2.1 request 50 54 04 00 01 01 07 0D and reply (24.12 V), checksums add up',
     Safety.NONE, 'actual motor voltage'),
    ('MOT_GetMotorPosition', 0x0108, MOTOR, N, '', F32, 'deg', 'high',
     'text: 4.1.8 "DpCode 0x0108"', Safety.NONE, 'motor position before the gear ratio'),
    ('MOT_GetLoadPosition', 0x0109, MOTOR, N, '', F32, 'deg', 'high',
     'order: only free slot between 0x0108 (4.1.8) and 0x010A (4.1.10); 4.1.9 heading '
     'lost, name from 4.1.1x remarks and 5.1.4', Safety.NONE,
     'load position after the gear ratio'),
    ('MOT_GetMotorSpeed', 0x010A, MOTOR, N, '', F32, 'deg/s', 'high',
     'text: 4.1.10 "Dx010A"', Safety.NONE, 'actual load speed'),
    ('MOT_GetPositionErr', 0x010E, MOTOR, N, '', F32, 'deg', 'high',
     'rev: 2.16.0 "GetPositionErr command was added - 0x010E"', Safety.NONE,
     'position error (absolute mode)'),
    ('MOT_GetIncPosition', 0x017C, MOTOR, N, '', F32, 'deg', 'high',
     'rev: 2.17 "MOT_GetIncPosition - 0x017C"', Safety.NONE, 'incremental encoder position'),
    ('MOT_GetEmgStopAxes', 0x017E, SYSTEM, N, '', BOOL, 'flag', 'high',
     'rev: 2.23.0 "MOT_GetEmgStopAxes - 0x017E"', Safety.NONE, 'emergency-stop flag'),
    # --- MOT set data (4.2) ------------------------------------------------------------
    ('MOT_SetAcceleration', 0x0130, MOTOR, F32, 'deg/s^2', N, '', 'high',
     'example: 7.1 50 54 08 00 01 01 30 42 C8 00 00 44 (100.0), checksum adds up',
     Safety.NONE, 'acceleration (> 0)'),
    ('MOT_SetSpeed', 0x0131, MOTOR, F32, 'deg/s', N, '', 'high',
     'example: 7.1 ... 01 31 41 DE 3D 71 08 (27.78), checksum adds up', Safety.NONE,
     'speed (position mode: profile speed; speed mode: signed velocity)'),
    ('MOT_SendPosition', 0x0132, MOTOR, F32, 'deg', N, '', 'high',
     'text: 2.1 "MOT_SendPosition has the OpCode of 0x0132"; example: 7.1 (13.487)',
     Safety.MOTION, 'position target, executed by MOT_Update'),
    ('MOT_SetActualPosition', 0x0133, MOTOR, F32, 'deg', N, '', 'high',
     'rev: 2.10.1 "MOT_SetActualPosition - 0x0133"', Safety.NONE,
     'redefine the current position (mind the software limits)'),
    ('MOT_Update', 0x0134, MOTOR, N, '', N, '', 'high',
     'example: 7.1 50 54 04 00 01 01 34 3A, checksum adds up', Safety.MOTION,
     'execute the motion set'),
    ('MOT_Homing', 0x0135, MOTOR, N, '', N, '', 'high',
     'order: only free slot between MOT_Update 0x0134 (7.1) and MOT_SetNegSWLS 0x0136 (rev '
     '2.10.1); section 4.2.6 follows MOT_Update', Safety.MOTION, 'run the stored homing'),
    ('MOT_SetPositionRelative', 0x0138, MOTOR, N, '', N, '', 'high',
     'example: 7.1 50 54 04 00 01 01 38 3E, checksum adds up', Safety.NONE, 'relative mode'),
    ('MOT_SetPositionAbsolute', 0x0139, MOTOR, N, '', N, '', 'high',
     'text: 4.2.8 "OpCode Dx0139"', Safety.NONE, 'absolute mode'),
    ('MOT_SetSpeedMode', 0x013A, MOTOR, N, '', N, '', 'high',
     'text fragment 4.2.9 "0x( A" + only slot between 0x0139 and 0x013B', Safety.NONE,
     'speed (velocity) mode'),
    ('MOT_SetPositionMode', 0x013B, MOTOR, N, '', N, '', 'high',
     'example: 7.1 50 54 04 00 01 01 3B 41, checksum adds up', Safety.NONE, 'position mode'),
    ('MOT_AxisOn', 0x013C, MOTOR, N, '', N, '', 'high', _ORDER_MOT + _AGREE, Safety.NONE,
     'power the motor (resumes a buffered motion)'),
    ('MOT_AxisOff', 0x013D, MOTOR, N, '', N, '', 'high', _ORDER_MOT + _AGREE, Safety.NONE,
     'power off the motor'),
    ('MOT_AxisReset', 0x013E, MOTOR, N, '', N, '', 'high', _ORDER_MOT + _AGREE, Safety.REBOOT,
     'reset the axis (it re-homes; wait 3 s)'),
    ('MOT_SetTum', 0x013F, MOTOR, N, '', N, '', 'high',
     _ORDER_MOT + '; the 7.1 example repeats 0x3B (a copy of SetPositionMode)' + _AGREE,
     Safety.NONE,
     'target update mode: rebuild the profile on each MOT_Update'),
    ('MOT_ResetFaults', 0x0143, MOTOR, N, '', N, '', 'high',
     _WITNESS + ' 0x0143; 4.2.15 prints only "Dx014", which it completes (was 0x0140 by '
     'section order: the run 0x013C..0x0143 has more slots than commands)', Safety.NONE,
     'reset latched faults of the axis'),
    ('MOT_SetShortPath', 0x014E, MOTOR, BOOL, 'flag', N, '', 'medium',
     _WITNESS + ' 0x014E; 4.2.16 prints only "Dx014"', Safety.NONE,
     'shortest way to an absolute position'),
    ('MOT_GetShortPath', 0x014F, MOTOR, N, '', BOOL, 'flag', 'medium',
     _WITNESS + ' 0x014F; 4.1.11 prints only "Dx014"', Safety.NONE, 'short-path flag'),
    ('MOT_GetMaxCurrent', 0x012E, MOTOR, N, '', F32, 'mA', 'medium',
     _WITNESS + ' 0x012E; 4.1.12 prints only "Dx0"', Safety.NONE, 'motor current limit'),
    ('MOT_SetMaxCurrent', 0x0166, MOTOR, F32, 'mA', N, '', 'medium',
     _WITNESS + ' 0x0166; 4.2.18 has no opcode line', Safety.NONE, 'motor current limit'),
    ('MOT_MotionComplete', 0x0144, MOTOR, N, '', N, '', 'high',
     'text: 4.2.19 "OpCode 0x0144"', Safety.NONE, 'wait for the current move before the next'),
    ('MOT_SaveMotorSetting', 0x0165, MOTOR, N, '', N, '', 'high',
     'rev: 2.10.1 "MOT_SaveMotorSetting - 0x0165"', Safety.NV_WRITE,
     'save motor settings to memory'),
    ('MOT_SetEmgStopAxes', 0x017D, SYSTEM, BOOL, 'flag', N, '', 'high',
     'text: 4.2.20 "OpCode 0x017D"; rev 2.23.0', Safety.NONE,
     'set (1: stop all axes, block motion) or clear (0) the emergency stop'),
    # --- software limit switches (4.16) ------------------------------------------------
    ('SWLS_SetNegSWLS', 0x0136, MOTOR, F32, 'deg', N, '', 'high',
     'text: 4.16.1 "OpCode 0x0136"; rev 2.10.1', Safety.NONE, 'negative software limit'),
    ('SWLS_SetPosSWLS', 0x0137, MOTOR, F32, 'deg', N, '', 'high',
     'text: 4.16.2 "OpCode 0x0137"; rev 2.10.1', Safety.NONE, 'positive software limit'),
    ('SWLS_ActivateSWLS', 0x0146, MOTOR, BOOL, 'flag', N, '', 'high',
     'rev: 2.10.1 "MOT_ActivateSWLS - 0x0146"; 4.16.3 fragment "Dx014.6"', Safety.NONE,
     'enable/disable the software limits'),
    ('SWLS_GetNegSWLS', 0x010C, MOTOR, N, '', F32, 'deg', 'high',
     'rev: 2.10.1 "MOT_GetNegSWLS - 0x010C"', Safety.NONE, 'negative software limit'),
    ('SWLS_GetPosSWLS', 0x010D, MOTOR, N, '', F32, 'deg', 'high',
     'rev: 2.10.1; text 4.16.5 "0x010D"', Safety.NONE, 'positive software limit'),
    ('SWLS_IsActiveSWLS', 0x0110, MOTOR, N, '', BOOL, 'flag', 'high',
     'rev: 2.10.1 "MOT_IsActiveSWLS - 0x0110"', Safety.NONE, 'software limits enabled'),
    # --- scanning (4.3); all sent to axis 0 ---------------------------------------------
    ('SCN_SetYawMin', 0x0400, SYSTEM, F32, 'deg', N, '', 'high',
     'order: 4.3.1-4.3.4 are the four slots below SCN_SetStepHeight 0x0404 (4.3.5 text); '
     'fragments "Dx04.0"' + _AGREE, Safety.NONE, 'left edge of the scan (motor position)'),
    ('SCN_SetYawMax', 0x0401, SYSTEM, F32, 'deg', N, '', 'high',
     'order: as SCN_SetYawMin' + _AGREE, Safety.NONE, 'right edge of the scan'),
    ('SCN_SetPitchMin', 0x0402, SYSTEM, F32, 'deg', N, '', 'high',
     'order: as SCN_SetYawMin' + _AGREE, Safety.NONE, 'bottom edge of the scan'),
    ('SCN_SetNumSteps', 0x0403, SYSTEM, U8, 'steps', N, '', 'high',
     'order: as SCN_SetYawMin; 4.3.4 heading lost, named after the NumSteps parameter'
     + _AGREE,
     Safety.NONE, 'rows (ZigZag/Snake) or rectangles (Square)'),
    ('SCN_SetStepHeight', 0x0404, SYSTEM, F32, 'deg', N, '', 'high',
     'text: 4.3.5 "Dx0404"', Safety.NONE, 'pitch step between rows'),
    ('SCN_SetScanSpeed', 0x0405, SYSTEM, F32, 'deg/s', N, '', 'high',
     'order: only slot between 0x0404 and 0x0406', Safety.NONE, 'yaw speed of the scan'),
    ('SCN_SetShortPath', 0x0406, SYSTEM, BOOL, 'flag', N, '', 'high',
     'text: 4.3.7 "0x0406"', Safety.NONE, 'short path between yaw min and max'),
    ('SCN_IsScanOn', 0x0407, SYSTEM, N, '', BOOL, 'flag', 'high',
     'order: only slot between 0x0406 and 0x0408', Safety.NONE, 'scan mode active'),
    ('SCN_StopScan', 0x0408, SYSTEM, N, '', N, '', 'high',
     'text: 4.3.9 "Dx0408"', Safety.NONE, 'stop both motors and leave scan mode'),
    ('SCN_StartScanZigZag', 0x040C, SYSTEM, N, '', N, '', 'high',
     'text: 4.3.13.1 "opcode 0x040C-0x040E" = the three start commands, in section order',
     Safety.MOTION, 'start a ZigZag scan'),
    ('SCN_StartScanSnake', 0x040D, SYSTEM, N, '', N, '', 'high',
     'text: 4.3.11 "Dx04.0D"; 4.3.13.1 range', Safety.MOTION, 'start a Snake scan'),
    ('SCN_StartScanSquare', 0x040E, SYSTEM, N, '', N, '', 'high',
     'text: 4.3.13.1 range', Safety.MOTION, 'start a Square scan'),
    # --- GPS and targets (4.4); axis byte ignored or target number ----------------------
    ('GPS_GetHeading', 0x0502, SYSTEM, N, '', F32, 'deg', 'high',
     'rev: 2.24.0 "GPS_GetHeading - 0x0502"', Safety.NONE, 'system heading'),
    ('GPS_GetLongitude', 0x0504, SYSTEM, N, '', F64, 'DDMM.mmmm', 'high',
     'text: 4.4.1 "Dx0504"', Safety.NONE, 'GPS longitude, east positive'),
    ('GPS_GetLatitude', 0x0505, SYSTEM, N, '', F64, 'DDMM.mmmm', 'low',
     'order: next after 0x0504 (4.4.2 follows 4.4.1), fragment "Dx050"; the witness table '
     'has no GPS group, so nothing confirms it (the node stops polling it if the device '
     'answers "opcode not recognized")', Safety.NONE,
     'GPS latitude, north positive'),
    ('GPS_PositionReady', 0x050A, SYSTEM, N, '', BOOL, 'flag', 'high',
     'text: 4.4.6 "Dx050A"', Safety.NONE, 'valid GPS position lock'),
    ('GPS_HeadingReady', 0x050B, SYSTEM, N, '', BOOL, 'flag', 'high',
     'text: 4.4.7 "Dx050B" (heading lost, named from its description)', Safety.NONE,
     'valid GPS heading'),
    ('GPS_isConnectedGPS', 0x050C, SYSTEM, N, '', BOOL, 'flag', 'medium',
     'order: next after 0x050B, fragment "Dx05("', Safety.NONE, 'GPS communicating'),
    ('GPS_GetTargetLLA', 0x050F, TARGET, N, '', LLA, 'deg,deg,m', 'high',
     'text: 5.1.3 "GetTargetLLA (0x050F)"', Safety.NONE, 'read target 1..15'),
    ('GPS_SetTargetLLA', 0x0510, TARGET, LLA, 'deg,deg,m', N, '', 'high',
     'text: 5.1.3 "SetTargetLLA (0x0510)"; example: 7.3 checksum 0xCC holds for 0x10 '
     '(the printed 0x2C is a copy of SetInsertedLLA)', Safety.NONE, 'store target 1..15'),
    ('GPS_GoToTarget', 0x0513, TARGET, N, '', N, '', 'high',
     'example: 7.3 opcode bytes 05 13 (its checksum 0xBC is wrong, 0x1F); 0x0511/0x0512 '
     'were the removed UTM commands (rev 2.9.0), 0x0514 follows', Safety.MOTION,
     'point the load at target 1..15'),
    ('GPS_ClearAllTargets', 0x0514, SYSTEM, N, '', N, '', 'high',
     'text: 4.4.13 "0x0514"', Safety.NONE, 'clear all 15 targets'),
    ('GPS_StartTargetLooping', 0x0516, SYSTEM, N, '', N, '', 'high',
     'rev: 2.12.0 "GPS_StartTargetLooping - 0x0516"', Safety.MOTION, 'loop over targets'),
    ('GPS_StopTargetLooping', 0x0517, SYSTEM, N, '', N, '', 'high',
     'rev: 2.12.0 "GPS_StopTargetLooping - 0x0517"', Safety.NONE, 'stop target looping'),
    ('GPS_ClearSingleTarget', 0x0528, TARGET, N, '', N, '', 'high',
     'rev: 2.23.0 "GPS_ClearSingleTarget - 0x0528"', Safety.NONE, 'clear one target'),
    ('GPS_SetTrackFreq', 0x0529, SYSTEM, U8, 'Hz', N, '', 'high', 'rev: 2.10.0', Safety.NONE,
     'target tracking frequency'),
    ('GPS_GetTrackFreq', 0x052A, SYSTEM, N, '', U8, 'Hz', 'high', 'rev: 2.10.0', Safety.NONE,
     'target tracking frequency'),
    ('GPS_SetInsertedLLA', 0x052C, SYSTEM, LLA, 'deg,deg,m', N, '', 'high',
     'rev: 2.10.0; example: 7.3.1 checksum 0xE1 adds up', Safety.NONE,
     'system position for non-tracker systems'),
    ('GPS_GetInsertedLLA', 0x052D, SYSTEM, N, '', LLA, 'deg,deg,m', 'high', 'rev: 2.10.0',
     Safety.NONE, 'inserted system position'),
    ('GPS_SetInsertedHeading', 0x052E, SYSTEM, F32, 'deg', N, '', 'high',
     'rev: 2.10.0; example: 7.3.1 (40.0) checksum 0x9D adds up', Safety.NONE,
     'system heading for non-tracker systems'),
    ('GPS_GetInsertedHeading', 0x052F, SYSTEM, N, '', F32, 'deg', 'high', 'rev: 2.10.0',
     Safety.NONE, 'inserted system heading'),
    ('GPS_SaveInsertedPos', 0x0530, SYSTEM, N, '', N, '', 'high', 'rev: 2.10.0',
     Safety.NV_WRITE, 'save position, heading and override flag'),
    ('GPS_SetOvdPosGPS', 0x0531, SYSTEM, BOOL, 'flag', N, '', 'high',
     'rev: 2.10.0; examples: 7.3.1/7.3.2 checksums 0x3C/0x3B add up', Safety.NONE,
     'override the GPS position with the inserted one'),
    ('GPS_GetOvdPosGPS', 0x0532, SYSTEM, N, '', BOOL, 'flag', 'high', 'rev: 2.10.0',
     Safety.NONE, 'override flag'),
    ('GPS_SetGpsIP', 0x0535, SYSTEM, IPV4, 'ip', N, '', 'high', 'rev: 2.19.0',
     Safety.NETWORK, 'IP address of the GPS unit (after reboot)'),
    ('GPS_GetGpsIP', 0x0536, SYSTEM, N, '', IPV4, 'ip', 'high', 'rev: 2.19.0', Safety.NONE,
     'IP address of the GPS unit'),
    ('GPS_EnGpsRead', 0x0537, SYSTEM, BOOL, 'flag', N, '', 'high', 'rev: 2.19.0',
     Safety.NONE, 'enable GPS reading over TCP'),
    ('GPS_GetEnGpsRead', 0x0538, SYSTEM, N, '', BOOL, 'flag', 'high', 'rev: 2.19.0',
     Safety.NONE, 'GPS reading enabled'),
    ('GPS_SetPlatformState', 0x0CBB, SYSTEM, U8, '0 static/1 dynamic', N, '', 'high',
     'rev: 2.24.0 lists 0x0CBB and 0x0CBC both as "SetPlatformState"; the setter comes '
     'first (4.4.32) and the getter 4.4.33 prints "Dx0CB"', Safety.NONE,
     'static or dynamic platform'),
    ('GPS_GetPlatformState', 0x0CBC, SYSTEM, N, '', U8, '0 static/1 dynamic', 'high',
     'rev: 2.24.0 (second entry, see GPS_SetPlatformState)', Safety.NONE,
     'static or dynamic platform'),
    # --- IMU (4.5) ----------------------------------------------------------------------
    ('IMU_IsReadyImu', 0x0601, SYSTEM, N, '', BOOL, 'flag', 'medium',
     'order: the slot before IMU_GetRoll 0x0602 (4.5.1 precedes 4.5.2)', Safety.NONE,
     'IMU connected and ready'),
    ('IMU_GetRoll', 0x0602, SYSTEM, N, '', F32, 'deg', 'high',
     'example: 2.2.2/7.2 50 54 04 00 00 06 02 0C and reply (30.184), checksums add up',
     Safety.NONE, 'roll -180..180'),
    ('IMU_GetPitch', 0x0603, SYSTEM, N, '', F32, 'deg', 'high',
     'order: only slot between 0x0602 and 0x0604', Safety.NONE, 'pitch -180..180'),
    ('IMU_GetYaw', 0x0604, SYSTEM, N, '', F32, 'deg', 'high', 'text: 4.5.4 "Dx0604"',
     Safety.NONE, 'yaw 0..360'),
    ('IMU_GetGyroX', 0x0605, SYSTEM, N, '', F32, 'deg/s', 'high', 'rev: 2.9.0', Safety.NONE,
     'gyro X rate'),
    ('IMU_GetGyroY', 0x0606, SYSTEM, N, '', F32, 'deg/s', 'high', 'rev: 2.9.0; text 4.5.6',
     Safety.NONE, 'gyro Y rate'),
    ('IMU_GetGyroZ', 0x0607, SYSTEM, N, '', F32, 'deg/s', 'high', 'rev: 2.9.0', Safety.NONE,
     'gyro Z rate'),
    ('IMU_GetTemperature', 0x0637, SYSTEM, N, '', F32, 'degC', 'high', 'rev: 2.9.0',
     Safety.NONE, 'IMU temperature'),
    ('IMU_GetPressure', 0x0638, SYSTEM, N, '', F32, 'kPa', 'high',
     'rev: 2.9.0; text 4.5.10 "Dx0638"', Safety.NONE, 'pressure'),
    ('IMU_Leveling', 0x016C, MOTOR, N, '', N, '', 'high',
     'rev: 2.12.0 "IMU_HomingIMU - 0x016C", renamed Leveling in 2.14.0', Safety.MOTION,
     'drive the axis to the IMU levelling angle'),
    ('IMU_setLevelingValue', 0x0C6B, MOTOR, F32, 'deg', N, '', 'high',
     'rev: 2.12.0 "IMU_setHomeValueIMU - 0x0C6B"; text 4.5.12 "Dx0C6B"', Safety.NONE,
     'levelling angle of the axis'),
    ('IMU_getLevelingValue', 0x0C6C, MOTOR, N, '', F32, 'deg', 'high',
     'rev: 2.12.0 "IMU_getHomeValueIMU - 0x0C6C"', Safety.NONE, 'levelling angle'),
    ('IMU_setIMULoadOffset', 0x0C6D, IMU_AXIS, F32, 'deg', N, '', 'high', 'rev: 2.13.6',
     Safety.NONE, 'offset for a load-mounted IMU'),
    ('IMU_getIMULoadOffset', 0x0C6E, IMU_AXIS, N, '', F32, 'deg', 'high', 'rev: 2.13.6',
     Safety.NONE, 'offset for a load-mounted IMU'),
    ('IMU_setIMUBodyOffset', 0x0C78, IMU_AXIS, F32, 'deg', N, '', 'high', 'rev: 2.13.6',
     Safety.NONE, 'offset for a body-mounted IMU'),
    ('IMU_getIMUBodyOffset', 0x0C79, IMU_AXIS, N, '', F32, 'deg', 'high', 'rev: 2.13.6',
     Safety.NONE, 'offset for a body-mounted IMU'),
    ('IMU_setIMUBaseOffset', 0x0C7A, IMU_AXIS, F32, 'deg', N, '', 'high', 'rev: 2.13.6',
     Safety.NONE, 'offset for a base-mounted IMU'),
    ('IMU_getIMUBaseOffset', 0x0C7B, IMU_AXIS, N, '', F32, 'deg', 'high', 'rev: 2.13.6',
     Safety.NONE, 'offset for a base-mounted IMU'),
    ('IMU_getPanPositionByGyro', 0x064A, IMU_SENSOR, N, '', F32, 'deg', 'high',
     'rev: 2.18.0', Safety.NONE, 'pan angle integrated from the gyro'),
    ('IMU_getTiltPositionByGyro', 0x064B, IMU_SENSOR, N, '', F32, 'deg', 'high',
     'rev: 2.18.0; text 4.5.23 "Dx064B"', Safety.NONE, 'tilt angle from the gyro'),
    ('IMU_getRollPositionByGyro', 0x064C, IMU_SENSOR, N, '', F32, 'deg', 'high',
     'rev: 2.18.0', Safety.NONE, 'roll angle from the gyro'),
    ('IMU_getPanSpeedByGyro', 0x064D, IMU_SENSOR, N, '', F32, 'deg/s', 'high',
     'rev: 2.18.0; text 4.5.25 "0x064D"', Safety.NONE, 'pan rate from the gyro'),
    ('IMU_getTiltSpeedByGyro', 0x064E, IMU_SENSOR, N, '', F32, 'deg/s', 'high',
     'rev: 2.18.0', Safety.NONE, 'tilt rate from the gyro'),
    ('IMU_getRollSpeedByGyro', 0x064F, IMU_SENSOR, N, '', F32, 'deg/s', 'high',
     'order: only slot between 0x064E (rev 2.18.0) and 0x0650 (rev 2.21.0)', Safety.NONE,
     'roll rate from the gyro'),
    ('IMU_GyroDriftCompensation', 0x0650, IMU_SENSOR, N, '', N, '', 'high', 'rev: 2.21.0',
     Safety.NONE, 'measure the current yaw gyro drift'),
    ('IMU_ResetGyroDriftCompensation', 0x0651, IMU_SENSOR, N, '', N, '', 'high',
     'rev: 2.21.0', Safety.NONE, 'reset the drift to zero'),
    ('IMU_GetGyroDrift', 0x0652, IMU_SENSOR, N, '', F32, 'deg/s', 'high', 'rev: 2.21.0',
     Safety.NONE, 'calculated drift'),
    # --- communication (4.6) ------------------------------------------------------------
    ('COM_Reboot', 0x0700, SYSTEM, N, '', N, '', 'medium',
     _WITNESS + ' 0x0700 (was 0x0701 by section order; the document prints no opcode, '
     'and the witness puts Connect/Disconnect at 0x0702/0x0703 as the order does)',
     Safety.REBOOT, 'reboot the controller (about 20 s)'),
    ('COM_Connect', 0x0702, SYSTEM, N, '', N, '', 'high',
     'order: below COM_IsConnected 0x0704 (4.6.4 text)' + _AGREE
     + '. Over TCP the controller greets with its own COM_Connect packet (6.1), and the '
     'client answers with the opcode the controller used',
     Safety.NONE, 'start the conversation (activates both axes)'),
    ('COM_Disconnect', 0x0703, SYSTEM, N, '', N, '', 'high',
     'order: the slot below COM_IsConnected 0x0704' + _AGREE,
     Safety.NONE, 'end the conversation (motors off)'),
    ('COM_IsConnected', 0x0704, SYSTEM, N, '', BOOL, 'flag', 'high',
     'text: 4.6.4 "Dx0704"; rev 2.12.0', Safety.NONE, 'controller initialised'),
    ('COM_StartKeepAlive', 0x0705, SYSTEM, BOOL, 'flag', N, '', 'high', 'rev: 2.13.6',
     Safety.NONE, 'start/stop the keep-alive supervision'),
    ('COM_IsKeepAliveOn', 0x0706, SYSTEM, N, '', BOOL, 'flag', 'high',
     'rev: 2.13.6; text 4.6.6 "Dx0706"', Safety.NONE, 'keep-alive active'),
    ('COM_setKeepAliveTimeout', 0x0708, SYSTEM, U16, 'ms', N, '', 'high', 'rev: 2.13.6',
     Safety.NONE, 'keep-alive period'),
    ('COM_getKeepAliveTimeout', 0x0709, SYSTEM, N, '', U16, 'ms', 'high', 'rev: 2.13.6',
     Safety.NONE, 'keep-alive period'),
    ('COM_setKeepAliveCount', 0x071C, SYSTEM, U8, 'cycles', N, '', 'high', 'rev: 2.13.6',
     Safety.NONE, 'missed periods before the controller stops the axes'),
    ('COM_getKeepAliveCount', 0x071D, SYSTEM, N, '', U8, 'cycles', 'high', 'rev: 2.13.6',
     Safety.NONE, 'missed periods allowed'),
    ('COM_SysState', 0x0713, SYSTEM, N, '', U8, 'bits', 'high', 'rev: 2.12.0', Safety.NONE,
     'active operations (stabilisation, tracking, scanning, looping)'),
    ('COM_setDigitalIO', 0x0723, DIGITAL_IO, BOOL, 'flag', N, '', 'high', 'rev: 2.22.0',
     Safety.NONE, 'set/reset digital output 1..6'),
    ('COM_getDigitalIO', 0x0724, DIGITAL_IO, N, '', BOOL, 'flag', 'high', 'rev: 2.22.0',
     Safety.NONE, 'state of digital I/O 1..6'),
    ('COM_GetPn', 0x0C2D, SYSTEM, N, '', ASCII, '', 'medium',
     _WITNESS + ' 0x0C2D; 4.6.13 prints no opcode (was 0x0C48 by section order)',
     Safety.NONE, 'part number'),
    ('COM_GetSn', 0x0C2F, SYSTEM, N, '', U32, '', 'medium',
     _WITNESS + ' 0x0C2F; 4.6.14 prints no opcode (was 0x0C49 by section order)',
     Safety.NONE, 'serial number'),
    ('COM_GetFw', 0x0C4A, SYSTEM, N, '', ASCII, '', 'high', 'text: 4.6.15 "Dx0C4 A"',
     Safety.NONE, 'firmware revision'),
    ('COM_GetHw', 0x0C4C, SYSTEM, N, '', F32, '', 'high',
     _WITNESS + ' 0x0C4C, which completes 4.6.16\'s "Dx0C4" (was 0x0C4B by section order)',
     Safety.NONE, 'hardware revision'),
    ('COM_SetComType', 0x0719, SYSTEM, U8, '1 eth/2 232/3 422/4 485', N, '', 'medium',
     _WITNESS + ' 0x0719; 4.6.11 heading and opcode lost', Safety.NETWORK,
     'communication type after the next reboot'),
    # --- IP settings (4.7), TCP only ----------------------------------------------------
    ('IP_SetControllerIP', 0x070A, SYSTEM, IPV4, 'ip', N, '', 'high',
     'text: 4.7.1 "OpCode 0x070A"', Safety.NETWORK, 'new controller IP (after save+reboot)'),
    ('IP_SetControllerPort', 0x070B, SYSTEM, U16, 'port', N, '', 'high',
     'text: 4.7.3 "Dx070B"', Safety.NETWORK, 'new controller port'),
    ('IP_GetControllerPort', 0x070E, SYSTEM, N, '', U16, 'port', 'medium',
     _WITNESS + ' 0x070E; 4.7.4 prints no opcode', Safety.NONE, 'controller port'),
    ('IP_SetControllerSubnetMask', 0x071A, SYSTEM, IPV4, 'ip', N, '', 'medium',
     _WITNESS + ' 0x071A, the slot below the getter 0x071B (4.7.6); 4.7.5 prints no opcode',
     Safety.NETWORK, 'new subnet mask (after save+reboot)'),
    ('IP_GetControllerIP', 0x070D, SYSTEM, N, '', IPV4, 'ip', 'high',
     'text: 4.7.2 "OpCode 0x070D"', Safety.NONE, 'controller IP'),
    ('IP_SaveIP', 0x0710, SYSTEM, N, '', N, '', 'high', 'text: 4.7.7 "OpCode 0x0710"',
     Safety.NETWORK, 'save IP settings to memory'),
    ('IP_GetControllerSubnetMask', 0x071B, SYSTEM, N, '', IPV4, 'ip', 'high',
     'text: 4.7.6 "OpCode 0x071B"', Safety.NONE, 'controller subnet mask'),
    # --- stabilisation (4.8) ------------------------------------------------------------
    ('STB_StabilizationOn', 0x0800, SYSTEM, N, '', N, '', 'high',
     'order: 4.8.1/4.8.2 take 0x0800/0x0801, the only slots below the removed '
     'STB_StabMoveRel 0x0802 (rev 2.9.0)' + _AGREE, Safety.NONE,
     'stabilise at the current position'),
    ('STB_StabilizationOff', 0x0801, SYSTEM, N, '', N, '', 'high',
     'order: as STB_StabilizationOn' + _AGREE, Safety.NONE, 'stop stabilisation'),
    ('STB_IsStabActive', 0x0807, SYSTEM, N, '', BOOL, 'flag', 'high', 'rev: 2.21.0',
     Safety.NONE, 'stabilisation active'),
    ('STB_GetStabMinAccel', 0x083A, MOTOR, N, '', F32, 'deg/s^2', 'high',
     'text: 4.8.6 "Dx083A"', Safety.NONE, 'minimum stabilisation acceleration'),
    ('STB_GetDistanceToTarget', 0x082A, SYSTEM, N, '', F32, 'm', 'high',
     'text: 4.8.20 "Dx082A"', Safety.NONE, 'distance to target (roll compensation)'),
    ('STB_GetCentralAxes', 0x0826, CENTRAL_AXIS, N, '', F32, 'm', 'high',
     'text: 4.8.22 "Dx0826"', Safety.NONE, 'sensor-to-centre distance'),
    ('STB_SetRebalanceOn', 0x084F, MOTOR, BOOL, 'flag', N, '', 'high', 'rev: 2.17.1',
     Safety.NONE, 'enable the rebalance function'),
    ('STB_GetRebalanceOn', 0x0850, MOTOR, N, '', BOOL, 'flag', 'high', 'rev: 2.17.1',
     Safety.NONE, 'rebalance enabled'),
    ('STB_GetRebalanceStatus', 0x0851, MOTOR, N, '', BOOL, 'flag', 'high', 'rev: 2.17.1',
     Safety.NONE, '1 decelerating, 0 normal'),
    ('STB_SetFeedforwardGain', 0x0852, MOTOR, F32, '%', N, '', 'high', 'rev: 2.18.0',
     Safety.NONE, 'feed-forward percentage'),
    ('STB_GetFeedforwardGain', 0x0853, MOTOR, N, '', F32, '%', 'high', 'rev: 2.18.0',
     Safety.NONE, 'feed-forward percentage'),
    ('STB_SetAxisRadiusCompensation', 0x0854, COMPENSATION, BOOL, 'flag', N, '', 'high',
     'text: 4.8.23 "Dx0854"', Safety.NONE, 'tilt/roll compensation on/off'),
    ('STB_SetAxisStabEnable', 0x0857, MOTOR, BOOL, 'flag', N, '', 'high', 'rev: 2.19.0',
     Safety.NONE, 'stabilise this axis'),
    ('STB_GetAxisStabEnable', 0x0858, MOTOR, N, '', BOOL, 'flag', 'high', 'rev: 2.19.0',
     Safety.NONE, 'axis stabilisation enabled'),
    # --- stabilisation gains and settings (4.8.4-4.8.30): the document prints only some
    # opcodes (0x0D04, 0x0D09, 0x0D0A, 0x0D16, 0x0D18, 0x0D1A), every one of which the
    # witness table confirms; the witness settles the rest.
    ('STB_GetStabError', 0x0822, MOTOR, N, '', F32, 'deg', 'medium',
     _WITNESS + ' 0x0822; 4.8.4 prints no opcode', Safety.NONE,
     'stabilisation position error'),
    ('STB_SetStabMinAccel', 0x0839, MOTOR, F32, 'deg/s^2', N, '', 'high',
     _WITNESS + ' 0x0839, the slot below its getter 0x083A (4.8.6 text)', Safety.NONE,
     'minimum stabilisation acceleration'),
    ('STB_SetDistanceToTarget', 0x082B, SYSTEM, F32, 'm', N, '', 'medium',
     _WITNESS + ' 0x082B, next to its getter 0x082A (4.8.20 text); 4.8.19 prints "Dp" only',
     Safety.NONE, 'distance to target (roll compensation)'),
    ('STB_SetCentralAxes', 0x0825, CENTRAL_AXIS, F32, 'm', N, '', 'high',
     _WITNESS + ' 0x0825, the slot below its getter 0x0826 (4.8.22 text); 4.8.21 "Dx08"',
     Safety.NONE, 'sensor-to-centre distance'),
    ('STB_SaveStabilizationCfg', 0x0D07, SYSTEM, N, '', N, '', 'medium',
     _WITNESS + ' 0x0D07 (inside the speed-gain run 0x0D04..0x0D0A); 4.8.30 no opcode',
     Safety.NV_WRITE, 'save the stabilisation settings to controller memory'),
    ('STB_SetSpdKp', 0x0D04, MOTOR, F32, 'factor', N, '', 'high',
     'text: 4.8.7 "Dx0D04"' + _AGREE,
     Safety.NONE, 'Kp of the speed PID'),
    ('STB_GetSpdKp', 0x0D08, MOTOR, N, '', F32, 'factor', 'medium',
     _WITNESS + ' 0x0D08; no opcode printed',
     Safety.NONE, 'Kp of the speed PID'),
    ('STB_SetSpdKi', 0x0D05, MOTOR, F32, 'factor', N, '', 'medium',
     _WITNESS + ' 0x0D05; no opcode printed',
     Safety.NONE, 'Ki of the speed PID'),
    ('STB_GetSpdKi', 0x0D09, MOTOR, N, '', F32, 'factor', 'high',
     'text: 4.8.10 "Dx0D09"' + _AGREE,
     Safety.NONE, 'Ki of the speed PID'),
    ('STB_SetSpdKd', 0x0D06, MOTOR, F32, 'factor', N, '', 'medium',
     _WITNESS + ' 0x0D06; no opcode printed',
     Safety.NONE, 'Kd of the speed PID'),
    ('STB_GetSpdKd', 0x0D0A, MOTOR, N, '', F32, 'factor', 'high',
     'text: "Dx0D0A" printed under 4.8.11, whose neighbour 4.8.12 lost its heading' + _AGREE,
     Safety.NONE, 'Kd of the speed PID'),
    ('STB_SetPosKp', 0x0D16, MOTOR, F32, 'factor', N, '', 'high',
     'text: 4.8.13 "Dx0D16"' + _AGREE,
     Safety.NONE, 'Kp of the position PID'),
    ('STB_GetPosKp', 0x0D17, MOTOR, N, '', F32, 'factor', 'medium',
     _WITNESS + ' 0x0D17; no opcode printed',
     Safety.NONE, 'Kp of the position PID'),
    ('STB_SetPosKi', 0x0D18, MOTOR, F32, 'factor', N, '', 'high',
     'text: 4.8.15 "0x0D18"' + _AGREE,
     Safety.NONE, 'Ki of the position PID'),
    ('STB_GetPosKi', 0x0D19, MOTOR, N, '', F32, 'factor', 'medium',
     _WITNESS + ' 0x0D19; no opcode printed',
     Safety.NONE, 'Ki of the position PID'),
    ('STB_SetPosKd', 0x0D1A, MOTOR, F32, 'factor', N, '', 'high',
     'text: 4.8.17 "Dx0D1A"' + _AGREE,
     Safety.NONE, 'Kd of the position PID'),
    ('STB_GetPosKd', 0x0D1B, MOTOR, N, '', F32, 'factor', 'medium',
     _WITNESS + ' 0x0D1B; no opcode printed',
     Safety.NONE, 'Kd of the position PID'),
    # --- presets (4.9); preset number in the axis byte ----------------------------------
    ('PRST_GetPreset', 0x0D00, PRESET, N, '', PRESET_FMT, 'name+deg', 'high',
     'text: 5.1.4 "GetPreset (0x0D00)"', Safety.NONE, 'read preset 1..15'),
    ('PRST_SetPreset', 0x0D01, PRESET, PRESET_FMT, 'name+deg', N, '', 'high',
     'text: 5.1.4 "SetPreset (0x0D01)"', Safety.NONE, 'store preset 1..15'),
    ('PRST_GoToPreset', 0x0D02, PRESET, N, '', N, '', 'medium',
     'order: 4.9.3/4.9.4 take 0x0D02/0x0D03 after SetPreset 0x0D01', Safety.MOTION,
     'drive to preset 1..15'),
    ('PRST_ClearAll', 0x0D03, SYSTEM, N, '', N, '', 'medium', 'order: as PRST_GoToPreset',
     Safety.NONE, 'clear all presets'),
    ('PRST_StartPresetLooping', 0x0D11, SYSTEM, N, '', N, '', 'high', 'rev: 2.12.0',
     Safety.MOTION, 'loop over the stored presets'),
    ('PRST_StopPresetLooping', 0x0D12, SYSTEM, N, '', N, '', 'high', 'rev: 2.12.0',
     Safety.NONE, 'stop preset looping'),
    ('PRST_GetPresetFlag', 0x0D13, SYSTEM, N, '', U16, 'bits', 'high',
     'order: only slot between 0x0D12 (rev) and 0x0D14 (4.9.8 text)', Safety.NONE,
     'bit n set: preset n+1 stored'),
    ('PRST_ClearSinglePreset', 0x0D14, PRESET, N, '', N, '', 'high',
     'text: 4.9.8 "Dx0D14"', Safety.NONE, 'clear one preset'),
    ('PRST_SetLoopingDelay', 0x0D1C, SYSTEM, F32, 'ms', N, '', 'high', 'rev: 2.12.0',
     Safety.NONE, 'dwell between looped points (multiples of 80 ms)'),
    ('PRST_GetLoopingDelay', 0x0D1D, SYSTEM, N, '', F32, 'ms', 'high',
     'rev: 2.12.0; text 4.9.10 "D0x0D1D"', Safety.NONE, 'dwell between looped points'),
    ('CFG_SetGeneralSpd', 0x0D1E, MOTOR, F32, 'deg/s', N, '', 'high',
     'rev: 2.12.0 "PRST_SetPresetSpd - 0x0D1E", renamed GeneralSpd in 2.14.0', Safety.NONE,
     'speed of preset/target moves'),
    ('CFG_GetGeneralSpd', 0x0D1F, MOTOR, N, '', F32, 'deg/s', 'high',
     'rev: 2.12.0 "PRST_GetPresetSpd - 0x0D1F"', Safety.NONE, 'speed of preset/target moves'),
    # --- configuration (4.12) -----------------------------------------------------------
    ('CFG_setStartupReg', 0x0C51, MOTOR, U8, 'bits', N, '', 'high', 'rev: 2.12.0',
     Safety.NV_WRITE, 'operations activated at start-up'),
    ('CFG_getStartupReg', 0x0C52, MOTOR, N, '', U8, 'bits', 'high', 'rev: 2.12.0',
     Safety.NONE, 'operations activated at start-up'),
    ('CFG_setPosRange', 0x0C70, MOTOR, U8, 'range code', N, '', 'high',
     'rev: 2.12.0 (3.3)', Safety.NV_WRITE, 'position range 0..3'),
    ('CFG_getPosRange', 0x0C71, MOTOR, N, '', U8, 'range code', 'high',
     'rev: 2.12.0 (3.4 prints "setPosRange" twice; the second is the getter)', Safety.NONE,
     'position range'),
    # --- errors (4.10) ------------------------------------------------------------------
    ('ERR_CaptureSystemRegister', 0x0E01, SYSTEM, N, '', U16, 'bits', 'high', _ERR_TABLE,
     Safety.NONE, 'Capture System Register (CSR)'),
    ('ERR_ClearErrors', 0x0E02, SYSTEM, N, '', N, '', 'high', _ERR_TABLE, Safety.NONE,
     'clear the CSR'),
    ('ERR_GetDriverErrorString', 0x0E03, SYSTEM, N, '', ASCII, '', 'high', _ERR_TABLE,
     Safety.NONE, 'driver communication error'),
    ('ERR_GetSystemErrorString', 0x0E04, SYSTEM, N, '', ASCII, '', 'high',
     _ERR_TABLE + '; text 4.10.10 "DxX0E04"', Safety.NONE, 'system error'),
    ('ERR_GetLoadImuErrorString', 0x0E05, SYSTEM, N, '', ASCII, '', 'high', _ERR_TABLE,
     Safety.NONE, 'load IMU error'),
    ('ERR_GetBaseImuErrorString', 0x0E06, SYSTEM, N, '', ASCII, '', 'high', _ERR_TABLE,
     Safety.NONE, 'base IMU error'),
    ('ERR_GetGpsComErrorString', 0x0E07, SYSTEM, N, '', ASCII, '', 'high', _ERR_TABLE,
     Safety.NONE, 'GPS communication error'),
    ('ERR_GetGpsPosString', 0x0E08, SYSTEM, N, '', ASCII, '', 'high', _ERR_TABLE,
     Safety.NONE, 'GPS position error'),
    ('ERR_GetGpsHeadErrorString', 0x0E09, SYSTEM, N, '', ASCII, '', 'high', _ERR_TABLE,
     Safety.NONE, 'GPS heading error'),
    ('ERR_GetProtocolErrorString', 0x0E0A, SYSTEM, N, '', ASCII, '', 'high', _ERR_TABLE,
     Safety.NONE, 'protocol error (read after an 0xA6 NACK)'),
    ('ERR_CaptureMotorErrorRegister', 0x0E0B, MOTOR, N, '', U16, 'bits', 'high',
     'text: 4.10.6 "OpCode - 0xOEOB"', Safety.NONE, 'Capture Motor Error Register (CMER)'),
    ('ERR_GetAbsEncComErrorString', 0x0E0D, SYSTEM, N, '', ASCII, '', 'high',
     _ERR_TABLE + '; rev 2.13.6', Safety.NONE, 'absolute encoder communication error'),
    ('ERR_GetAbsEncCRCErrorString', 0x0E0E, SYSTEM, N, '', ASCII, '', 'high',
     _ERR_TABLE + '; rev 2.13.6', Safety.NONE, 'absolute encoder CRC error'),
    ('ERR_GetBodyImuErrorString', 0x0E0F, SYSTEM, N, '', ASCII, '', 'high',
     _ERR_TABLE + '; rev 2.13.6', Safety.NONE, 'body IMU error'),
    ('ERR_GetHomingErrorString', 0x0E10, SYSTEM, N, '', ASCII, '', 'high',
     _ERR_TABLE + '; rev 2.13.6', Safety.NONE, 'homing not completed'),
    ('ERR_OperationRegister', 0x0E12, MOTOR, N, '', U16, 'bits', 'high',
     'rev: 2.16.0 "New Error register was added operations error - 0x0E12"', Safety.NONE,
     'Operation Register'),
    # --- laser rangefinder (4.17); axis byte unused except for the measurement number -----
    ('LRF_SetManualDistance', 0x0300, SYSTEM, F32, 'm', N, '', 'high',
     'rev: 2.17 "LRF_SetRange - 0x0300"; 4.17.1 is that command renamed ("Set the range to '
     'the target"), first of the group' + _AGREE + ' (as LRF_SetRange)', Safety.NONE,
     'manual distance to the target'),
    ('LRF_GetManualDistance', 0x0301, SYSTEM, N, '', F32, 'm', 'high',
     'rev: 2.17 "LRF_GetRange - 0x0301" (renamed, as LRF_SetManualDistance)' + _AGREE,
     Safety.NONE,
     'manual distance to the target'),
    ('LRF_SetMinMeasurement', 0x0302, SYSTEM, U16, 'm', N, '', 'high', 'rev: 2.20.0',
     Safety.NONE, 'minimum of the measurement range'),
    ('LRF_GetMinMeasurement', 0x0303, SYSTEM, N, '', U16, 'm', 'high', 'rev: 2.20.0',
     Safety.NONE, 'minimum of the measurement range'),
    ('LRF_SetMaxMeasurement', 0x0304, SYSTEM, U16, 'm', N, '', 'high',
     'rev: 2.20.0; text 4.17.5 "Dx0304"', Safety.NONE, 'maximum of the measurement range'),
    ('LRF_GetMaxMeasurement', 0x0305, SYSTEM, N, '', U16, 'm', 'high', 'rev: 2.20.0',
     Safety.NONE, 'maximum of the measurement range'),
    ('LRF_SetFrequency', 0x0306, SYSTEM, U8, 'Hz', N, '', 'high', 'rev: 2.20.0', Safety.NONE,
     'measurement frequency'),
    ('LRF_GetFrequency', 0x0307, SYSTEM, N, '', U8, 'Hz', 'high', 'rev: 2.20.0', Safety.NONE,
     'measurement frequency'),
    ('LRF_StartMeasurement', 0x0308, SYSTEM, N, '', N, '', 'high',
     'order: rev 2.20.0 item 1.7 lost in the OCR; only slot between 0x0307 and 0x0309',
     Safety.NONE, 'start measuring'),
    ('LRF_StopMeasurement', 0x0309, SYSTEM, N, '', N, '', 'high', 'rev: 2.20.0', Safety.NONE,
     'stop measuring'),
    ('LRF_GetLRFDistance', 0x030A, MEASUREMENT, N, '', F32, 'm', 'high',
     'rev: 2.20.0; text 4.17.11 "Dx030A"', Safety.NONE,
     'measured distance (measurement 1 = current/last)'),
    ('LRF_SetDistanceSource', 0x030B, SYSTEM, U8, '0 manual/1 LRF', N, '', 'high',
     'rev: 2.20.0', Safety.NONE, 'distance source'),
    ('LRF_GetDistanceSource', 0x030C, SYSTEM, N, '', U8, '0 manual/1 LRF', 'high',
     'rev: 2.20.0', Safety.NONE, 'distance source'),
    ('LRF_GetTargetDistance', 0x030D, SYSTEM, N, '', F32, 'm', 'high', 'rev: 2.20.0',
     Safety.NONE, 'final distance (from the selected source)'),
    ('LRF_IsConnected', 0x030E, SYSTEM, N, '', BOOL, 'flag', 'high', 'rev: 2.20.0',
     Safety.NONE, 'rangefinder connected'),
    # --- servo control (4.19) -----------------------------------------------------------
    ('SRV_IsEnable', 0x0F71, SYSTEM, N, '', BOOL, 'flag', 'high', 'rev: 2.21.0',
     Safety.NONE, 'servo control enabled'),
    ('SRV_MoveTo', 0x0F78, SYSTEM, U8, 'position 1..3', N, '', 'high', 'rev: 2.21.0',
     Safety.MOTION, 'move the servo to a predefined position'),
    ('SRV_GetPosition', 0x0F79, SYSTEM, N, '', U8, 'position (4 unknown)', 'high',
     'rev: 2.21.0', Safety.NONE, 'servo position number'),
    # --- video tracking (4.11); camera index 0..3 in the group byte ----------------------
    ('VDT_setTrackingOn', 0x0A01, CAMERA, U8, '0 off/1 manual/2 auto', N, '', 'high',
     'text: 4.11.1 "OpCode 0x0A01"; rev 2.21.0', Safety.MOTION,
     'video tracking off (0), manual (1) or automatic (2): the pedestal follows the target'),
    ('VDT_isTrackingOn', 0x0A02, CAMERA, N, '', BOOL, 'flag', 'high',
     'text: 4.11.2 "OpCode 0x0A02"; rev 2.21.0', Safety.NONE, 'video tracking active'),
    ('VDT_isAutoModeOn', 0x0A04, CAMERA, N, '', BOOL, 'flag', 'high',
     'text: 4.11.3 "Dx0A04"; rev 2.21.0', Safety.NONE, 'automatic tracking mode'),
    ('VDT_isTargetDetected', 0x0A13, CAMERA, N, '', BOOL, 'flag', 'high',
     'rev: 2.21.0 "VDT_isTargetDetected - 0x0A13" (4.11.4 prints "Dx0A")', Safety.NONE,
     'a target is detected'),
    ('VDT_GetTargetsList', 0x0732, CAMERA, N, '', TARGETS, 'width x height', 'high',
     'text: 5.1.5 "GetTargetsList command (0x0732)" (named VDT_ here: it lists the '
     "tracker's detected targets; the camera index is assumed in the group byte as for "
     'every VDT command)', Safety.NONE, 'up to 5 detected targets, (0, 0) when absent'),
    # --- Pelco-D settings (4.13): fourteen commands in section order fill 0x0C80..0x0C8D;
    # the printed 0x0C84 (5th), 0x0C86 (7th), 0x0C8A (11th) and 0x0C8D (14th) all agree.
    ('PELCOD_EnPelcoD', 0x0C80, SYSTEM, BOOL, 'flag', N, '', 'medium',
     _ORDER_PELCO + ' below the first anchor 0x0C84 (fragments "Dx0C8")', Safety.NETWORK,
     'enable Pelco-D control over RS-485 (the axes then obey Pelco-D messages)'),
    ('PELCOD_IsActivePelcoD', 0x0C81, SYSTEM, N, '', BOOL, 'flag', 'medium',
     _ORDER_PELCO + ' below the first anchor 0x0C84 (fragments "Dx0C8")', Safety.NONE,
     'Pelco-D support enabled'),
    ('PELCOD_SetAddress', 0x0C82, SYSTEM, U8, 'address', N, '', 'medium',
     _ORDER_PELCO + ' below the first anchor 0x0C84 (fragments "Dx0C8")', Safety.NETWORK,
     'Pelco-D device address'),
    ('PELCOD_GetAddress', 0x0C83, SYSTEM, N, '', U8, 'address', 'medium',
     _ORDER_PELCO + ' below the first anchor 0x0C84 (fragments "Dx0C8")', Safety.NONE,
     'Pelco-D device address'),
    ('PELCOD_SetAxisNum', 0x0C84, PELCO_AXIS, U8, 'system axis', N, '', 'high',
     'text: 4.13.5 "Dx0C84"', Safety.NONE,
     'system axis driven by this Pelco-D axis'),
    ('PELCOD_GetAxisNum', 0x0C85, PELCO_AXIS, N, '', U8, 'system axis', 'high',
     _ORDER_PELCO + ' between two printed anchors', Safety.NONE,
     'system axis driven by this Pelco-D axis'),
    ('PELCOD_SetMinSpd', 0x0C86, MOTOR, F32, 'deg/s', N, '', 'high',
     'text: 4.13.7 "Dx0C86"', Safety.NONE,
     'lowest speed of the Pelco-D speed range'),
    ('PELCOD_GetMinSpd', 0x0C87, MOTOR, N, '', F32, 'deg/s', 'high',
     _ORDER_PELCO + ' between two printed anchors', Safety.NONE,
     'lowest speed of the Pelco-D speed range'),
    ('PELCOD_SetMaxSpd', 0x0C88, MOTOR, F32, 'deg/s', N, '', 'high',
     _ORDER_PELCO + ' between two printed anchors', Safety.NONE,
     'highest speed of the Pelco-D speed range'),
    ('PELCOD_GetMaxSpd', 0x0C89, MOTOR, N, '', F32, 'deg/s', 'high',
     _ORDER_PELCO + ' between two printed anchors', Safety.NONE,
     'highest speed of the Pelco-D speed range'),
    ('PELCOD_SetTurboSpd', 0x0C8A, PAN, F32, 'deg/s', N, '', 'high',
     'text: 4.13.11 "Dx0C8A"', Safety.NONE,
     'Pelco-D turbo speed (pan only)'),
    ('PELCOD_GetTurboSpd', 0x0C8B, PAN, N, '', F32, 'deg/s', 'high',
     _ORDER_PELCO + ' between two printed anchors', Safety.NONE,
     'Pelco-D turbo speed (pan only)'),
    ('PELCOD_SetAccel', 0x0C8C, MOTOR, F32, 'deg/s^2', N, '', 'high',
     _ORDER_PELCO + ' between two printed anchors', Safety.NONE,
     'Pelco-D acceleration'),
    ('PELCOD_GetAccel', 0x0C8D, MOTOR, N, '', F32, 'deg/s^2', 'high',
     'text: 4.13.14 "Dx0C8D"', Safety.NONE,
     'Pelco-D acceleration'),
    # --- relays (4.14): only two opcodes are printed; 0x0D24..0x0D2A has 7 slots for the
    # 10 commands up to RLY_GetModuleIP, so section order cannot place the others.
    ('RLY_ActivateModule', 0x0D24, SYSTEM, BOOL, 'flag', N, '', 'high',
     'text: 4.14.1 "OpCode Dx0D24"', Safety.NONE, 'activate the relay module'),
    ('RLY_GetModuleIP', 0x0D2A, SYSTEM, N, '', IPV4, 'ip', 'high',
     'text: 4.14.10 "Dx0D2A"', Safety.NONE, 'IP address of the relay module'),
    # --- dual gimbals (4.15): camera and synchronisation functions only. The weapon and
    # CapSnap entries (active weapon, ballistic offset, safety, load, I/O, bullets) are out
    # of scope and deliberately absent. Axis byte: 1 pan, 2 tilt, 4 pan 2, 5 tilt 2.
    ('DG_SetSyncMode', 0x0FA0, SYSTEM, BOOL, 'flag', N, '', 'medium',
     _WITNESS + ' 0x0FA0, the slot below DG_SetInnerMode 0x0FA1 (4.15.2 text)',
     Safety.MOTION, 'synchronise both gimbals (gimbal 2 follows gimbal 1)'),
    ('DG_SetInnerMode', 0x0FA1, SYSTEM, BOOL, 'flag', N, '', 'high',
     'text: 4.15.2 "OpCode 0x0FA1"' + _AGREE, Safety.NONE,
     'inner (1) or outer (0) azimuth mode of gimbal 2'),
    ('DG_IsSyncMode', 0x0FA2, SYSTEM, N, '', BOOL, 'flag', 'high',
     _WITNESS + ' 0x0FA2, completing 4.15.3 "Dx0FA"', Safety.NONE, 'sync mode active'),
    ('DG_IsInnerMode', 0x0FA3, SYSTEM, N, '', BOOL, 'flag', 'high',
     _WITNESS + ' 0x0FA3, completing 4.15.4 "DxOFA"', Safety.NONE, 'inner mode active'),
    ('DG_GetPosDiff', 0x0FA5, DG_PAIR, N, '', F32, 'deg', 'high',
     _WITNESS + ' 0x0FA5, completing 4.15.5 "Dx0FA"', Safety.NONE,
     'angle between the paired axes of the two gimbals'),
    ('DG_SetMaxDiff', 0x0FA6, DG_PAIR, F32, 'deg', N, '', 'high',
     'rev: 2.17.0 "DG_SetMaxDiff - 0x0FA6"' + _AGREE, Safety.NONE,
     'largest difference counted as synchronised (min 0.0026)'),
    ('DG_GetMaxDiff', 0x0FA7, DG_PAIR, N, '', F32, 'deg', 'high',
     'rev: 2.17.0 "DG_GetMaxDiff - 0x0FA7"' + _AGREE, Safety.NONE,
     'largest difference counted as synchronised'),
    ('DG_IsAxesSynced', 0x0FA8, SYSTEM, N, '', BOOL, 'flag', 'high',
     'rev: 2.19.0 "DG_IsAxesSynced - 0x0FA8"', Safety.NONE, 'both axis pairs within MaxDiff'),
    ('DG_GoToCamera', 0x0FA9, SYSTEM, N, '', N, '', 'high',
     _WITNESS + ' 0x0FA9, completing 4.15.9 "Dx0FAS"', Safety.MOTION,
     'drive gimbal 1 to the current position of gimbal 2'),
    ('DG_SetSyncSpd', 0x0FAA, DG_PAIR, F32, 'deg/s', N, '', 'high',
     'rev: 2.17.0 "DG_SetSyncSpd - 0x0FAA"' + _AGREE, Safety.NONE,
     'speed of the synchronisation (gimbal 1 axes)'),
    ('DG_SetMainGimbal', 0x0FAB, SYSTEM, U8, 'gimbal 1/2', N, '', 'medium',
     _WITNESS + ' 0x0FAB; 4.15.11 prints "DxO0FAE" (E read for B; 0x0FAE would break '
     'the Set/Get pair with DG_GetMainGimbal 0x0FAC)', Safety.NONE,
     'gimbal that scans, presets and targets move'),
    ('DG_GetMainGimbal', 0x0FAC, SYSTEM, N, '', U8, 'gimbal 1/2', 'high',
     _WITNESS + ' 0x0FAC, completing 4.15.12 "DxO0FA"; 4.15.12 prints the setter\'s '
     'formats, a getter returns the uint8', Safety.NONE, 'main gimbal'),
    ('DG_CTC', 0x0FB0, SYSTEM, N, '', N, '', 'high',
     'rev: 2.15.1 "DG_SetSightingIn - 0x0FB0", renamed CTC in 2.17.0' + _AGREE, Safety.NONE,
     'centre-to-centre: store the gimbal 2 origin offsets (all axes on one target)'),
    ('DG_GetCTCoffset', 0x0FB1, DG_GIMBAL2, N, '', F32, 'deg', 'high',
     'rev: 2.15.1 "DG_GetSightingInOffset - 0x0FB1", renamed' + _AGREE, Safety.NONE,
     'centre-to-centre offset of a gimbal 2 axis'),
    ('DG_ResetCTCoffset', 0x0FB2, SYSTEM, N, '', N, '', 'high',
     'rev: 2.15.1 "DG_ResetSightingInOffset - 0x0FB2", renamed' + _AGREE, Safety.NONE,
     'clear the centre-to-centre offsets'),
    ('DG_GetSyncSpd', 0x0FB5, DG_PAIR, N, '', F32, 'deg/s', 'high',
     'rev: 2.17.0 "DG_GetSyncSpd - 0x0FB5"' + _AGREE, Safety.NONE,
     'speed of the synchronisation'),
    ('DG_IsBoresightEn', 0x0FB9, SYSTEM, N, '', BOOL, 'flag', 'high',
     'rev: 2.17.1; text 4.15.23 "Dx0FB9"' + _AGREE, Safety.NONE,
     'boresight (pointing-axis intersection) enabled'),
    ('DG_SetActiveCamera', 0x0FBA, SYSTEM, U8, 'camera 1..4', N, '', 'high',
     'rev: 2.17.0 "DG_SetActiveCamera - 0x0FBA"' + _AGREE, Safety.NONE,
     'camera whose dimensions the boresight uses'),
    ('DG_GetActiveCamera', 0x0FBB, SYSTEM, N, '', U8, 'camera 1..4', 'high',
     'rev: 2.17.0; text 4.15.22 "DxOFBB"' + _AGREE, Safety.NONE, 'active camera'),
    ('DG_GetBoresightOffset', 0x0FBC, DG_AXIS, N, '', F32, 'deg', 'high',
     'rev: 2.17.1 "DG_GetBoresightOffset - 0x0FBC"' + _AGREE, Safety.NONE,
     'boresight addition to the go-to-camera position of an axis'),
    ('DG_IsSynchronizing', 0x0FCA, SYSTEM, N, '', BOOL, 'flag', 'high',
     'rev: 2.22.0 "IsSynchronizing - 0x0FCA"', Safety.NONE, 'synchronisation running'),
]

COMMANDS: dict[str, Command] = {}
BY_OPCODE: dict[int, Command] = {}
for _row in _TABLE:
    _name, _opcode, _axis = _row[:3]
    _cmd = Command(_name, _opcode, _axis, arg=_row[3], arg_unit=_row[4], ret=_row[5],
                   ret_unit=_row[6], confidence=_row[7], evidence=_row[8], safety=_row[9],
                   summary=_row[10])
    if _cmd.name in COMMANDS or _cmd.opcode in BY_OPCODE:
        raise RuntimeError(f'duplicate command table entry {_cmd.name} 0x{_cmd.opcode:04X}')
    COMMANDS[_cmd.name] = _cmd
    BY_OPCODE[_cmd.opcode] = _cmd
del _row, _cmd

# Commands of the in-scope groups whose opcode could not be established; never encoded.
UNRESOLVED: dict[str, str] = {
    'GPS_GetAltitude': '4.4.4 has no opcode line; 0x0506..0x0509 all fit; no witness',
    'GPS_GetSatellites': '4.4.5 has no opcode line; 0x0506..0x0509 all fit; no witness',
    'GPS_StartTargetTracking': '4.4.16 no opcode; 0x0515 or 0x0518.. (tracker systems only)',
    'GPS_StopTargetTracking': '4.4.17 no opcode (tracker systems only)',
    'GPS_GetStartupStatus': '4.4.18 no opcode',
    'IMU_Reset': '4.5.8 heading lost, "Dx060" only; 0x0608..0x0636 all fit',
    'IMU_setGyroFilterGain': 'rev 2.18.0 says get=0x0640/set=0x0641 but 4.5.20 prints '
                             '"0x064(0" for the setter: contradictory; no witness',
    'IMU_getGyroFilterGain': 'see IMU_setGyroFilterGain',
    'STB_GetAxisRadiusCompensation': '4.8.24 no opcode; the witness lists only the older '
                                     'STB_Set/GetRollCompensation 0x0C76/0x0C77, not this '
                                     'command (its setter is 0x0854)',
    'SWLS_SetHandler/GetHandler/SetOffsetValue/GetOffsetValue/SetSlowdownValue/'
    'GetSlowdownValue': '4.16.7-4.16.12 print only fragments ("Dx( 6", "Dx0 B"); no witness',
    'RLY_IsActivateModule/SetRelay/GetRelay/SetRelayPeriod/SetRelayJogging/GetModuleErr/'
    'RstComModule/SetModuleIP/SetNumRelays/GetNumRelays':
        'only 0x0D24 (4.14.1) and 0x0D2A (4.14.10) are printed; 7 slots for 10 commands, so '
        'section order does not hold; no witness',
    'DG_SetStabGimbal/GetStabGimbal': '4.15.13/4.15.14 print "DXOFA" only; 0x0FA4, 0x0FAD..'
                                      '0x0FAF all fit; not in the witness',
}


def command(name: str) -> Command:
    """Look up a command by name (case-insensitive); :class:`UnknownCommand` says why not."""
    found = COMMANDS.get(name)
    if found is None:
        lowered = {key.lower(): cmd for key, cmd in COMMANDS.items()}
        found = lowered.get(name.lower())
    if found is not None:
        return found
    if name in UNRESOLVED:
        raise UnknownCommand(f'{name} is not encoded: opcode not established ({UNRESOLVED[name]})')
    raise UnknownCommand(f'unknown command {name!r}; see capture_driver.protocol.COMMANDS')


def encode(name: str, axis: int | None = None, value: Any = None, group: int = 0) -> bytes:
    """Request bytes for the named command."""
    return command(name).encode(axis, value, group)


def markdown_table() -> str:
    """The command table as Markdown (doc/command_table.md is generated from this)."""
    lines = [
        '| command | opcode | axis byte | argument | reply | confidence | safety | evidence |',
        '|---|---|---|---|---|---|---|---|',
    ]
    for cmd in sorted(COMMANDS.values(), key=lambda c: c.opcode):
        arg = '-' if cmd.arg is DataType.NONE else ' '.join(
            filter(None, (cmd.arg.value, cmd.arg_unit)))
        ret = 'ACK' if cmd.ret is DataType.NONE else ' '.join(
            filter(None, (cmd.ret.value, cmd.ret_unit)))
        safety = '' if cmd.safety is Safety.NONE else cmd.safety.value
        evidence = cmd.evidence.replace('|', '/')
        lines.append(f'| `{cmd.name}` | 0x{cmd.opcode:04X} | {cmd.axis.name} | {arg} | {ret} '
                     f'| {cmd.confidence} | {safety} | {evidence} |')
    lines += ['', '## Not encoded (opcode not established)', '',
              '| command(s) | why |', '|---|---|']
    lines += [f'| `{name}` | {why} |' for name, why in UNRESOLVED.items()]
    return '\n'.join(lines) + '\n'
