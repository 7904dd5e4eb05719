"""Status and error registers of section 4.10 as named flags with severities.

Severities: ERROR for conditions the spec says stop motion or need a reset / power cycle
(MER/DER errors, fault status, over-current, ...), WARN for limit switches, protection
warnings and "not completed" operations, OK for informational status bits. The node turns
the active flags into diagnostic key/values and the worst level into the status level.

Gaps in the OCR'd tables (kept as reserved, i.e. not decoded):
* SRL (4.10.4) lists only bits 7, 8, 10, 14 and 15; the other rows were lost.
* MER bit 15 "Enable status of drive" lost its notes; CMER bit 3 of the same meaning says
  1 = drive disabled, so MER bit 15 is read the same way.
* MSR rows 6..11 are garbled ("Positive limit switch 2 - _'F'ﬁ;;:?g;red"); the "2" is the
  OCR of the "0 - not triggered / 1 - triggered" notes, so bit set = triggered.
"""

from __future__ import annotations

from dataclasses import dataclass

from gimbal_driver_common.diagnostics import ActiveFlag, Level, RegisterFlag, decode_register

OK, WARN, ERROR = Level.OK, Level.WARN, Level.ERROR


@dataclass(frozen=True)
class Register:
    name: str
    command: str  # the getter in commands.COMMANDS
    per_axis: bool
    flags: tuple[RegisterFlag, ...]

    def decode(self, value: int) -> list[ActiveFlag]:
        return decode_register(value, self.flags, self.name)


def _f(bit: int, name: str, level: Level, description: str, active_low: bool = False):
    return RegisterFlag(bit, name, level, description, active_low)


MER = Register('MER', 'MOT_MerRegister', True, (
    _f(0, 'can_bus_error', ERROR, 'CAN bus error: check CAN wiring'),
    _f(1, 'short_circuit', ERROR, 'short-circuit protection'),
    _f(2, 'invalid_setup_table', ERROR, 'drive has an invalid setup table'),
    _f(3, 'control_error', ERROR, 'control error: position or speed not reached'),
    _f(4, 'communication_error', ERROR, 'serial communication error with the drive'),
    _f(5, 'position_sensor_error', ERROR, 'position sensor error'),
    _f(6, 'positive_limit_switch', WARN, 'positive limit switch (LSP) active'),
    _f(7, 'negative_limit_switch', WARN, 'negative limit switch (LSN) active'),
    _f(8, 'over_current', ERROR, 'over-current: current reached the protection limit'),
    _f(9, 'i2t_error', ERROR, 'drive or motor I2T error: check for mechanical blockage'),
    _f(10, 'motor_over_temperature', ERROR, 'motor over temperature'),
    _f(11, 'drive_over_temperature', ERROR, 'drive over temperature'),
    _f(12, 'over_voltage', ERROR, 'over voltage: check the power supply'),
    _f(13, 'under_voltage', ERROR, 'under voltage: check the power supply'),
    _f(14, 'command_error', WARN, 'command error (update during AxisOn or cancelable call)'),
    _f(15, 'drive_disabled', WARN, 'drive enable input inactive'),
))

DER = Register('DER', 'MOT_DerRegister', True, (
    _f(0, 'tml_stack_overflow', ERROR, 'TML stack overflow'),
    _f(1, 'tml_stack_underflow', ERROR, 'TML stack underflow'),
    _f(2, 'homing_not_available', WARN, 'homing not available'),
    _f(3, 'function_not_available', WARN, 'function not available'),
    _f(4, 'update_ignored', WARN, 'UPD (update) ignored'),
    _f(5, 'cancelable_call_ignored', WARN, 'cancelable call ignored'),
    _f(6, 'software_positive_limit', WARN, 'software positive limit switch triggered'),
    _f(7, 'software_negative_limit', WARN, 'software negative limit switch triggered'),
    _f(8, 'invalid_s_curve', WARN, 'invalid S-curve profile'),
    _f(9, 'update_ignored_s_curve', WARN, 'UPD ignored for S-curve'),
    _f(10, 'encoder_broken_wire', ERROR, 'encoder broken wire'),
    _f(11, 'motionless_start_failed', ERROR, 'motionless start failed (brushless)'),
    _f(12, 'tml_heartbeat_ignored', WARN, 'TML heartbeat ignored: check wiring'),
    _f(13, 'self_check_error', ERROR, 'self-check error'),
))

SRH = Register('SRH', 'MOT_SrhRegister', True, (
    _f(0, 'drive_initialized', OK, 'drive initialisation performed'),
    _f(1, 'position_trigger_1', OK, 'position trigger 1 reached'),
    _f(2, 'position_trigger_2', OK, 'position trigger 2 reached'),
    _f(3, 'position_trigger_3', OK, 'position trigger 3 reached'),
    _f(4, 'position_trigger_4', OK, 'position trigger 4 reached'),
    _f(5, 'auto_run', OK, 'auto run mode enabled'),
    _f(6, 'positive_limit_event', WARN, 'positive limit switch event'),
    _f(7, 'negative_limit_event', WARN, 'negative limit switch event'),
    _f(8, 'capture_event', OK, 'capture event/interrupt'),
    _f(9, 'target_reached', OK, 'target command reached'),
    _f(10, 'motor_i2t_warning', WARN, 'motor I2T warning limit reached'),
    _f(11, 'drive_i2t_warning', WARN, 'drive I2T warning limit reached'),
    _f(13, 'gear_ratio_reached', OK, 'gear ratio reached (electronic gearing)'),
    _f(14, 'cam_reference_reached', OK, 'reference position reached (electronic camming)'),
    _f(15, 'fault', ERROR, 'drive/motor in fault status: reset faults and AxisOn'),
))

SRL = Register('SRL', 'MOT_SrlRegister', True, (
    _f(7, 'homing_warning', WARN, 'homing/function call warning'),
    _f(8, 'homing_active', OK, 'homing/function call active'),
    _f(10, 'motion_complete', OK, 'motion complete'),
    _f(14, 'event_occurred', OK, 'event/interrupt triggered'),
    _f(15, 'axis_on', OK, 'axis is on'),
    _f(15, 'axis_off', WARN, 'axis is off', active_low=True),
))

MSR = Register('MSR', 'MOT_MsrRegister', True, (
    _f(0, 'drive_initialized', OK, 'drive initialisation performed'),
    _f(1, 's_curve_update_denied', WARN, 'S-curve update denied'),
    _f(2, 'software_protection', WARN, 'software protection triggered'),
    _f(3, 'control_error', ERROR, 'control error'),
    _f(5, 'position_wrap_around', OK, 'position wrap-around'),
    _f(6, 'positive_limit_switch', WARN, 'positive limit switch triggered'),
    _f(7, 'negative_limit_switch', WARN, 'negative limit switch triggered'),
    _f(8, 'position_capture', OK, 'position capture triggered'),
    _f(9, 'motion_complete', OK, 'motion complete'),
    _f(10, 'in_contour_mode', OK, 'in contour mode'),
    _f(11, 'event_set', OK, 'programmed event occurred'),
    _f(13, 'axis_on', OK, 'axis is on'),
    _f(14, 'event_status', OK, 'event set for update'),
    _f(15, 'motion_mode_update', OK, 'motion mode update'),
))

CMER = Register('CMER', 'ERR_CaptureMotorErrorRegister', True, (
    _f(0, 'fault', ERROR, 'drive/motor in fault status: reset faults and AxisOn'),
    _f(1, 'axis_on', OK, 'axis is on'),
    _f(1, 'axis_off', WARN, 'axis is off', active_low=True),
    _f(2, 'motion_complete', OK, 'motion complete'),
    _f(3, 'drive_disabled', WARN, 'drive disabled: check the enable input'),
    _f(4, 'under_voltage', ERROR, 'under voltage: check the power supply'),
    _f(5, 'over_voltage', ERROR, 'over voltage: check the power supply'),
    _f(6, 'i2t_error', ERROR, 'drive or motor I2T error: check for mechanical blockage'),
    _f(7, 'over_current', ERROR, 'over-current: current reached the protection limit'),
    _f(8, 'negative_limit_switch', WARN, 'negative limit switch (LSN) active'),
    _f(9, 'positive_limit_switch', WARN, 'positive limit switch (LSP) active'),
    _f(10, 'control_error', ERROR, 'control error: position or speed not reached'),
    _f(11, 'short_circuit', ERROR, 'short-circuit protection'),
    _f(12, 'encoder_broken_wire', ERROR, 'encoder broken wire'),
    _f(13, 'software_negative_limit', WARN, 'software negative limit switch triggered'),
    _f(14, 'software_positive_limit', WARN, 'software positive limit switch triggered'),
    _f(15, 'can_bus_error', ERROR, 'CAN bus error'),
))

CSR = Register('CSR', 'ERR_CaptureSystemRegister', False, (
    _f(0, 'driver_communication_error', ERROR, 'no communication with a motor driver'),
    _f(1, 'system_error', ERROR, 'system error'),
    _f(2, 'base_imu_error', ERROR, 'base IMU error'),
    _f(3, 'load_imu_error', ERROR, 'load IMU error'),
    _f(4, 'gps_communication_error', WARN, 'GPS communication error'),
    _f(5, 'gps_position_error', WARN, 'GPS position not ready'),
    _f(6, 'gps_heading_error', WARN, 'GPS heading not ready'),
    _f(7, 'protocol_error', WARN, 'protocol error'),
    _f(8, 'body_imu_error', ERROR, 'body IMU error'),
    _f(9, 'abs_encoder_crc_error', ERROR, 'absolute encoder CRC error'),
    _f(10, 'abs_encoder_communication_error', ERROR, 'absolute encoder communication error'),
    _f(11, 'homing_not_completed', WARN, 'homing not completed'),
))

# CSR bit -> the command returning its detailed error string (4.10.9-4.10.20, table 4.10.22).
CSR_ERROR_STRINGS: dict[int, str] = {
    0: 'ERR_GetDriverErrorString',
    1: 'ERR_GetSystemErrorString',
    2: 'ERR_GetBaseImuErrorString',
    3: 'ERR_GetLoadImuErrorString',
    4: 'ERR_GetGpsComErrorString',
    5: 'ERR_GetGpsPosString',
    6: 'ERR_GetGpsHeadErrorString',
    7: 'ERR_GetProtocolErrorString',
    8: 'ERR_GetBodyImuErrorString',
    9: 'ERR_GetAbsEncCRCErrorString',
    10: 'ERR_GetAbsEncComErrorString',
    11: 'ERR_GetHomingErrorString',
}

OPERATION = Register('OPR', 'ERR_OperationRegister', True, (
    _f(0, 'position_error', WARN, 'deviation between current and target angle (absolute mode)'),
    _f(1, 'homing_not_completed', WARN, 'homing not completed'),
    _f(2, 'levelling_not_completed', WARN, 'levelling not completed'),
    _f(3, 'synchronizing_not_completed', WARN, 'synchronising not completed (dual gimbals)'),
))

SYSTEM_STATE = Register('SYS', 'COM_SysState', False, (
    _f(0, 'stabilization', OK, 'stabilisation active'),
    _f(1, 'tracking', OK, 'tracking active'),
    _f(2, 'scanning', OK, 'scanning active'),
    _f(3, 'preset_looping', OK, 'preset looping active'),
    _f(4, 'target_looping', OK, 'target looping active'),
))

REGISTERS: dict[str, Register] = {
    r.name: r for r in (MER, DER, SRH, SRL, MSR, CMER, CSR, OPERATION, SYSTEM_STATE)
}
AXIS_REGISTERS = tuple(r for r in REGISTERS.values() if r.per_axis)
SYSTEM_REGISTERS = tuple(r for r in REGISTERS.values() if not r.per_axis)

# Bits the simulator and client use directly.
SRL_HOMING_ACTIVE = 1 << 8
SRL_MOTION_COMPLETE = 1 << 10
SRL_AXIS_ON = 1 << 15
SRH_TARGET_REACHED = 1 << 9
SRH_FAULT = 1 << 15
CSR_HOMING_NOT_COMPLETED = 1 << 11
CSR_PROTOCOL_ERROR = 1 << 7  # set by an 0xA6 NACK, cleared by ERR_ClearErrors
OPR_HOMING_NOT_COMPLETED = 1 << 1
SYS_SCANNING = 1 << 2
SYS_PRESET_LOOPING = 1 << 3
SYS_STABILIZATION = 1 << 0
