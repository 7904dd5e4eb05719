"""The raw ``~/command`` service's text: which table entries it sends and how its
arguments and results read (no ROS). Separate from the adapter: pure text rules.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from gimbal_driver_common.errors import InvalidRequest

from .protocol import COMMANDS, DataType, GeoPoint, PresetRecord, Safety

# MOTION commands have a dedicated, limit-checked interface; ~/command points there.
DEDICATED = {
    'MOT_SendPosition': 'joint_command or ~/move_to',
    'MOT_Update': 'joint_command or ~/move_to (the driver sends the whole motion profile)',
    'MOT_Homing': '~/home',
    'SCN_StartScanZigZag': '~/start_scan', 'SCN_StartScanSnake': '~/start_scan',
    'SCN_StartScanSquare': '~/start_scan',
    'PRST_GoToPreset': '~/goto_preset', 'PRST_StartPresetLooping': '~/start_preset_loop',
    'GPS_GoToTarget': '~/goto_lla',
    'GPS_StartTargetLooping': '~/start_target_loop',
    'IMU_Leveling': '~/level',
    'VDT_setTrackingOn': '~/set_tracking (the tracker drives pan and tilt)',
}
# Motion commands ~/command sends anyway: the auxiliary servo is not a joint; the
# dual-gimbal synchronisation moves the axes under the controller's own (software-limit)
# control with no driver-side target to check, so it gets the axis-state check (off/faulted
# axes refuse) but no limit check. Video tracking has its own service (~/set_tracking).
ALLOWED_MOTION = {'SRV_MoveTo', 'DG_SetSyncMode', 'DG_GoToCamera'}
JOINT_MOTION = ALLOWED_MOTION - {'SRV_MoveTo'}
OPT_IN = {
    Safety.NV_WRITE: 'allow_nv_write',
    Safety.REBOOT: 'allow_reboot',
    Safety.NETWORK: 'allow_network_config',
}



def parse_arguments(dtype: DataType, args: Sequence[str]) -> Any:
    """Text arguments of ~/command to the value a table entry takes."""
    try:
        if dtype is DataType.NONE:
            if args:
                raise ValueError('this command takes no argument')
            return None
        if dtype is DataType.LLA:
            lon, lat, alt = (float(a) for a in _split(args, 3))
            return GeoPoint(lon, lat, alt)
        if dtype is DataType.PRESET:
            name, *angles = _split(args, 7)  # _split checks there are 7
            a1, a2, a3, a4, a5, a6 = (float(a) for a in angles)
            return PresetRecord(name, (a1, a2, a3, a4, a5, a6))
        (text,) = _split(args, 1)
        if dtype in (DataType.F32, DataType.F64):
            return float(text)
        if dtype is DataType.BOOL:
            lowered = text.strip().lower()
            if lowered in ('1', 'true', 'on', 'yes'):
                return 1
            if lowered in ('0', 'false', 'off', 'no'):
                return 0
            raise ValueError(f'{text!r} is not a boolean (true/false/1/0)')
        if dtype in (DataType.U8, DataType.U16, DataType.U32):
            return int(text, 0)
        return text
    except ValueError as exc:
        raise InvalidRequest(f'bad argument for {dtype.value}: {exc}') from None


def _split(args: Sequence[str], count: int) -> list[str]:
    items = [a for arg in args for a in arg.replace(',', ' ').split()] if count > 1 else list(args)
    if len(items) != count:
        raise ValueError(f'expected {count} argument(s), got {len(items)}')
    return items


def format_result(cmd_name: str, value: Any) -> list[str]:
    cmd = COMMANDS[cmd_name]
    unit = f' {cmd.ret_unit}' if cmd.ret_unit else ''
    if isinstance(value, GeoPoint):
        return [f'longitude={value.longitude:.8f} deg', f'latitude={value.latitude:.8f} deg',
                f'altitude={value.altitude:.3f} m']
    if isinstance(value, PresetRecord):
        return [f'name={value.name}', *(f'{axis}={angle:.4f} deg' for axis, angle in zip(
            ('azimuth', 'elevation', 'roll', 'x', 'y', 'z'), value.angles, strict=True))]
    if cmd.ret is DataType.TARGETS:
        return [f'target{i}={width}x{height}' for i, (width, height) in enumerate(value, 1)]
    if cmd.ret_unit == 'bits':
        return [f'0x{value:04X}']
    if isinstance(value, float):
        return [f'{value:.6g}{unit}']
    return [f'{value}{unit}']
