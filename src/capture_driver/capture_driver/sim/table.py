"""Capture simulator: the command table, one handler row per command the model executes."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..protocol import Frame, GeoPoint, PresetRecord, degrees_to_ddmm
from .axis import AxisModel
from .handlers import CommandHandlers, _error_text

if TYPE_CHECKING:
    from .model import PedestalModel
    from .transport import CaptureSession


#: one handler per command: (model, request frame, decoded argument, session) -> the value
#: a getter returns (None for the rest); a command without an entry stores and returns
#: its value (PedestalModel._generic)
Handler = Callable[['PedestalModel', Frame, Any, 'CaptureSession'], Any]


def _value(value: object) -> Handler:
    """A constant answer."""
    return lambda model, frame, arg, session: value


def _get(attribute: str) -> Handler:
    """A model attribute."""
    return lambda model, frame, arg, session: getattr(model, attribute)


def _set(attribute: str, convert: Callable[[Any], Any] = lambda arg: arg) -> Handler:
    """Store the argument in a model attribute."""
    return lambda model, frame, arg, session: setattr(model, attribute, convert(arg))


def _of_axis(read: Callable[[AxisModel], Any]) -> Handler:
    """A value of the addressed axis (0xA6 for an axis the pedestal has not)."""
    return lambda model, frame, arg, session: read(model._axis(frame))


def _assign(attribute: str, value: object) -> Handler:
    """Set a model attribute to ``value`` (the argument is not used)."""
    return lambda model, frame, arg, session: setattr(model, attribute, value)


def _put(attribute: str) -> Handler:
    """Store the argument in a model dict under the number in the axis byte."""
    return lambda model, frame, arg, session: getattr(model, attribute).__setitem__(
        frame.axis, arg)


def _remove(attribute: str) -> Handler:
    """Forget the entry of a model dict numbered in the axis byte."""
    return lambda model, frame, arg, session: getattr(model, attribute).pop(frame.axis, None)


def _clear(attribute: str) -> Handler:
    """Empty a model dict."""
    return lambda model, frame, arg, session: getattr(model, attribute).clear()


def _measuring(on: bool) -> Handler:
    """LRF_Start/StopMeasurement: the range reads 850 m while measuring (sim)."""
    return lambda model, frame, arg, session: model.stored.__setitem__(('LRF_measuring', 0), on)


def _set_axis(attribute: str, value: object = None) -> Handler:
    """Store the argument (or ``value``) in an attribute of the addressed axis."""
    return lambda model, frame, arg, session: setattr(
        model._axis(frame), attribute, arg if value is None else value)


def _of_target(read: Callable[[PedestalModel, int], Any]) -> Handler:
    """A value of the preset, target or IMU sensor numbered in the axis byte."""
    return lambda model, frame, arg, session: read(model, frame.axis)


def _of_camera(read: Callable[[PedestalModel, int], Any]) -> Handler:
    """A value of the video-tracker camera in the group byte (4.11)."""
    return lambda model, frame, arg, session: read(model, model._camera(frame))


def _error_string(bit: int, text: str) -> Handler:
    """An ERR_Get...String: ``text`` while its CSR bit is set, else empty (4.10.22)."""
    return lambda model, frame, arg, session: _error_text(model, bit, text)


def _scan_parameter(key: str, convert: Callable[[Any], Any] = lambda arg: arg) -> Handler:
    return lambda model, frame, arg, session: model.scan_params.__setitem__(key, convert(arg))


def _scan(pattern: str) -> Handler:
    return lambda model, frame, arg, session: model._start_scan(pattern)


def _motor_position(model: PedestalModel, frame: Frame, arg: object, session: object) -> float:
    return model._axis(frame).position * model.gear_ratio


M = CommandHandlers
HANDLERS: dict[str, Handler] = {
    # --- COM
    'COM_Connect': M._connect,
    'COM_Disconnect': M._disconnect,
    'COM_Reboot': M._disconnect,
    'COM_IsConnected': _value(True),
    'COM_StartKeepAlive': _set('keepalive_on', bool),
    'COM_IsKeepAliveOn': _get('keepalive_on'),
    'COM_setKeepAliveTimeout': _set('keepalive_timeout_ms'),
    'COM_getKeepAliveTimeout': _get('keepalive_timeout_ms'),
    'COM_setKeepAliveCount': _set('keepalive_count'),
    'COM_getKeepAliveCount': _get('keepalive_count'),
    'COM_SysState': M._system_state,
    'COM_GetSn': _get('serial_number'),
    'COM_GetFw': _get('firmware'),
    'COM_GetHw': _get('hardware_revision'),
    'COM_GetPn': _get('part_number'),
    'COM_setDigitalIO': M._digital_io,
    'COM_getDigitalIO': M._digital_io,
    # --- MOT reads and registers
    'MOT_GetLoadPosition': _of_axis(lambda axis: axis.position),
    'MOT_GetMotorPosition': _motor_position,
    'MOT_GetIncPosition': _motor_position,
    'MOT_GetMotorSpeed': _of_axis(lambda axis: axis.velocity),
    'MOT_GetMotorCurrent': _of_axis(lambda axis: axis.current_ma if axis.axis_on else 0.0),
    'MOT_GetMotorVoltage': _value(24.12),
    'MOT_GetPositionErr': _of_axis(
        lambda axis: axis.target - axis.position if axis.target is not None else 0.0),
    'MOT_GetEmgStopAxes': _get('emergency_stop'),
    'MOT_MerRegister': _of_axis(AxisModel.mer),
    'MOT_DerRegister': _of_axis(AxisModel.der),
    'MOT_SrhRegister': _of_axis(AxisModel.srh),
    'MOT_SrlRegister': _of_axis(AxisModel.srl),
    'MOT_MsrRegister': _of_axis(AxisModel.msr),
    'ERR_CaptureMotorErrorRegister': _of_axis(AxisModel.cmer),
    'ERR_OperationRegister': _of_axis(AxisModel.operation),
    'ERR_CaptureSystemRegister': M._system_register,
    'ERR_ClearErrors': M._clear_errors,
    # --- error strings (4.10.22): each while its CSR bit is set
    'ERR_GetDriverErrorString': M._driver_error_string,
    'ERR_GetSystemErrorString': _error_string(1, 'General system error'),
    'ERR_GetBaseImuErrorString': _error_string(2, 'Fail to sync with IMU'),
    'ERR_GetLoadImuErrorString': _error_string(3, 'No communication with IMU'),
    'ERR_GetGpsComErrorString': _error_string(4, 'No communication with the GPS'),
    'ERR_GetGpsPosString': _error_string(5, 'The position of the GPS is not ready'),
    'ERR_GetGpsHeadErrorString': _error_string(6, 'The heading of the GPS is not ready'),
    'ERR_GetHomingErrorString': _error_string(11, 'Pan & Tilt Homing are not completed'),
    'ERR_GetProtocolErrorString': _get('protocol_error'),
    # --- MOT motion (7.1 profile, MOT_Update executes it)
    'MOT_SetAcceleration': M._set_acceleration,
    'MOT_SetSpeed': _set_axis('speed'),
    'MOT_SendPosition': _set_axis('pending_position'),
    'MOT_SetPositionRelative': _set_axis('relative', True),
    'MOT_SetPositionAbsolute': _set_axis('relative', False),
    'MOT_SetSpeedMode': M._speed_mode,
    'MOT_SetPositionMode': M._position_mode,
    'MOT_Update': M._update,
    'MOT_Homing': M._homing,
    'MOT_AxisOn': M._axis_on,
    'MOT_AxisOff': M._axis_off,
    'MOT_AxisReset': M._axis_reset,
    'MOT_ResetFaults': M._reset_faults,
    'MOT_SetActualPosition': M._set_actual_position,
    'MOT_SetEmgStopAxes': M._emergency_stop,
    # --- software limits
    'SWLS_SetNegSWLS': M._set_negative_limit,
    'SWLS_SetPosSWLS': M._set_positive_limit,
    'SWLS_ActivateSWLS': M._activate_limits,
    'SWLS_GetNegSWLS': _of_axis(lambda axis: axis.swls_neg),
    'SWLS_GetPosSWLS': _of_axis(lambda axis: axis.swls_pos),
    'SWLS_IsActiveSWLS': _of_axis(lambda axis: axis.swls_active),
    # --- scans (4.3)
    'SCN_SetYawMin': _scan_parameter('yaw_min'),
    'SCN_SetYawMax': _scan_parameter('yaw_max'),
    'SCN_SetPitchMin': _scan_parameter('pitch_min'),
    'SCN_SetNumSteps': _scan_parameter('steps'),
    'SCN_SetStepHeight': _scan_parameter('step_height'),
    'SCN_SetScanSpeed': _scan_parameter('speed'),
    'SCN_SetShortPath': _scan_parameter('short_path', int),
    'SCN_IsScanOn': lambda model, frame, arg, session: model.scan is not None,
    'SCN_StopScan': M._stop_scan,
    'SCN_StartScanZigZag': _scan('zigzag'),
    'SCN_StartScanSnake': _scan('snake'),
    'SCN_StartScanSquare': _scan('square'),
    # --- presets (the number in the axis byte)
    'PRST_GetPreset': _of_target(lambda model, n: model.presets.get(n, PresetRecord(''))),
    'PRST_SetPreset': _put('presets'),
    'PRST_GoToPreset': M._goto_preset_request,
    'PRST_ClearAll': _clear('presets'),
    'PRST_ClearSinglePreset': _remove('presets'),
    'PRST_GetPresetFlag': lambda model, frame, arg, session: sum(
        1 << (i - 1) for i in model.presets),
    'PRST_StartPresetLooping': M._start_preset_looping,
    'PRST_StopPresetLooping': _assign('preset_looping', None),
    'PRST_SetLoopingDelay': _set('looping_delay_ms', lambda arg: max(float(arg), 0.0)),
    'PRST_GetLoopingDelay': _get('looping_delay_ms'),
    'CFG_SetGeneralSpd': M._set_general_speed,
    'CFG_GetGeneralSpd': _of_axis(lambda axis: axis.general_speed),
    # --- stabilisation
    'STB_StabilizationOn': M._stabilization_on,
    'STB_StabilizationOff': M._stabilization_off,
    'STB_IsStabActive': _get('stabilization'),
    # --- IMU (sim: the sensor sits on the load)
    'IMU_IsReadyImu': _value(True),
    'IMU_GetRoll': lambda model, frame, arg, session: (
        model.axes[3].position if 3 in model.axes else 0.0),
    'IMU_GetPitch': lambda model, frame, arg, session: model.axes[2].position,
    'IMU_GetYaw': lambda model, frame, arg, session: (
        (model.gps_heading + model.axes[1].position) % 360.0),
    'IMU_GetGyroX': lambda model, frame, arg, session: (
        model.axes[3].velocity if 3 in model.axes else 0.0),
    'IMU_GetGyroY': lambda model, frame, arg, session: model.axes[2].velocity,
    'IMU_GetGyroZ': lambda model, frame, arg, session: model.axes[1].velocity,
    'IMU_GetTemperature': _value(36.5),
    'IMU_GetPressure': _value(101.3),
    'IMU_Leveling': M._leveling,
    'IMU_GyroDriftCompensation': M._measure_drift,
    'IMU_ResetGyroDriftCompensation': M._reset_gyro_drift,
    'IMU_GetGyroDrift': _of_target(lambda model, sensor: model.gyro_drift[sensor]),
    # --- laser rangefinder
    'LRF_IsConnected': _value(True),
    'LRF_StartMeasurement': _measuring(True),
    'LRF_StopMeasurement': _measuring(False),
    'LRF_GetLRFDistance': M._lrf_distance,
    'LRF_GetTargetDistance': M._target_distance,
    # --- GPS (positions DDMM.mmmm, 4.4.1) and targets (the number in the axis byte)
    'GPS_GetLongitude': lambda model, frame, arg, session: degrees_to_ddmm(
        model.gps_position.longitude),
    'GPS_GetLatitude': lambda model, frame, arg, session: degrees_to_ddmm(
        model.gps_position.latitude),
    'GPS_GetHeading': lambda model, frame, arg, session: model._system_position()[1],
    'GPS_PositionReady': lambda model, frame, arg, session: model.gps_present and model.gps_fix,
    'GPS_HeadingReady': lambda model, frame, arg, session: model.gps_present and model.gps_fix,
    'GPS_isConnectedGPS': _get('gps_present'),
    'GPS_SetTargetLLA': _put('targets'),
    'GPS_GetTargetLLA': _of_target(
        lambda model, n: model.targets.get(n, GeoPoint(0.0, 0.0, 0.0))),
    'GPS_ClearSingleTarget': _remove('targets'),
    'GPS_ClearAllTargets': _clear('targets'),
    'GPS_SetInsertedLLA': _set('inserted_position'),
    'GPS_GetInsertedLLA': _get('inserted_position'),
    'GPS_SetInsertedHeading': _set('inserted_heading'),
    'GPS_GetInsertedHeading': _get('inserted_heading'),
    'GPS_SetOvdPosGPS': _set('override_gps', bool),
    'GPS_GetOvdPosGPS': _get('override_gps'),
    'GPS_GoToTarget': M._go_to_target,
    'GPS_StartTargetLooping': M._start_target_looping,
    'GPS_StopTargetLooping': _assign('target_looping', None),
    # --- video tracker (the camera in the group byte)
    'VDT_setTrackingOn': M._set_tracking,
    'VDT_isTrackingOn': _of_camera(CommandHandlers._tracking_active),
    'VDT_isAutoModeOn': _of_camera(lambda model, camera: model.tracker_mode[camera] == 2),
    'VDT_isTargetDetected': _of_camera(
        lambda model, camera: bool(model.detected_targets[camera])),
    'VDT_GetTargetsList': _of_camera(lambda model, camera: model.detected_targets[camera][:5]),
}
del M
