"""The Capture pedestal's capability objects (no ROS): homing, the device's preset slots,
its own scans, where it stands (geolocation) and aiming at a point through its GPS
target slot. Each wraps the :class:`~.device.CaptureDevice` it serves.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from gimbal_driver_common import geodesy
from gimbal_driver_common.config import ControllerConfig, scan_joints
from gimbal_driver_common.device import (
    DevicePresets,
    DeviceScans,
    Geolocation,
    Homing,
    TargetPointing,
)
from gimbal_driver_common.errors import DeviceRefused, InvalidRequest, LinkError
from gimbal_driver_common.scan import ScanError, ScanRequest, check_scan

from .device_requests import SCAN_COMMANDS
from .errors import REQUEST_ERRORS, NotConnected
from .protocol import GeoPoint, PresetRecord

if TYPE_CHECKING:
    from .device import CaptureDevice

LOG = logging.getLogger('capture_driver.capabilities')

MAX_PRESETS = 15



def _attached_config(device: CaptureDevice) -> ControllerConfig:
    """The controller's configuration (refused, not crashed, before it is attached)."""
    return device.attached_config()

class CaptureHoming(Homing):
    """MOT_Homing per axis; progress from SRL bit 8 (homing active) and the load position."""

    def __init__(self, device: CaptureDevice) -> None:
        self.device = device

    def home(self, joints: Sequence[str], report: Callable[[str], None],
             cancelled: threading.Event) -> str:
        device, client = self.device, self.device.client
        try:
            device.programs.leave()
            for joint in joints:
                client.run('MOT_Homing', device.axis(joint))
            deadline = time.monotonic() + device.settings.home_timeout
            while True:
                if cancelled.is_set():
                    raise DeviceRefused('homing cancelled')
                states = []
                for joint in joints:
                    axis = device.axis(joint)
                    srl = client.request('MOT_SrlRegister', axis)
                    der = client.request('MOT_DerRegister', axis)
                    if der & (1 << 2):
                        raise DeviceRefused(f'{joint}: the drive reports homing not available '
                                            '(DER bit 2); contact Capture support')
                    position = device.from_device(
                        joint, client.request('MOT_GetLoadPosition', axis))
                    states.append((joint, bool(srl & (1 << 8)), position))
                report(', '.join(f'{j}: {"homing" if active else "done"} at {p:+.4f} rad'
                                 for j, active, p in states))
                if not any(active for _, active, _ in states):
                    break
                if time.monotonic() > deadline:
                    raise DeviceRefused(f'homing not finished within home_timeout '
                                        f'{device.settings.home_timeout:g} s')
                cancelled.wait(0.1)
            unfinished = [j for j in joints
                          if client.request('ERR_OperationRegister', device.axis(j)) & (1 << 1)]
            if unfinished:
                raise DeviceRefused(f'homing not completed for {unfinished} '
                                    f'({client.request("ERR_GetHomingErrorString")})')
        except NotConnected as exc:
            raise LinkError(f'homing failed: {exc}') from exc
        except REQUEST_ERRORS as exc:
            raise DeviceRefused(f'homing failed: {exc}') from exc
        device.expire_status()
        return f'homed: {", ".join(joints)}'


class CapturePresets(DevicePresets):
    """The device's 15 preset slots (PRST_*), every index on the device: angles are stored
    in device degrees per axis (azimuth, elevation, roll = axis 1..3)."""

    def __init__(self, device: CaptureDevice) -> None:
        self.device = device

    @staticmethod
    def _check_index(index: int) -> None:
        if not 1 <= index <= MAX_PRESETS:
            raise InvalidRequest(f'preset index {index} outside 1..{MAX_PRESETS} '
                                 '(device presets)')

    def positions(self, record: PresetRecord) -> dict[str, float]:
        device = self.device
        return {j: device.from_device(j, record.angles[device.axis(j) - 1])
                for j in device.joint_names}

    def checked_record(self, index: int) -> PresetRecord:
        """A stored slot whose pose is inside the joint limits."""
        client = self.device.client
        if index not in client.preset_indices():
            raise DeviceRefused(f'preset {index} is empty on the device')
        record = client.get_preset(index)
        self.device.check_pose(self.positions(record), f'preset {index} ({record.name})')
        return record

    def set(self, index: int, name: str, positions: dict[str, float] | None) -> str:
        self._check_index(index)
        if not name.isascii() or len(name) > 16:
            raise InvalidRequest(f'preset name {name!r} must be ASCII, at most 16 characters')
        device, client = self.device, self.device.client
        angles = [0.0] * 6
        for joint in device.joint_names:
            axis = device.axis(joint)
            if positions is not None and joint in positions:
                angles[axis - 1] = device.to_device(joint, positions[joint])
            else:
                angles[axis - 1] = client.request('MOT_GetLoadPosition', axis)
        client.set_preset(index, name, angles)
        return f'device preset {index} ({name or "unnamed"}) stored'

    def goto(self, index: int, speed: float) -> str:
        """Check the slot against the limits; speed > 0 sets CFG_SetGeneralSpd per axis
        (it stays set on the device); then PRST_GoToPreset."""
        self._check_index(index)
        device, client = self.device, self.device.client
        record = self.checked_record(index)
        limits = _attached_config(device).limits
        if speed > 0:
            for joint in device.joint_names:
                if speed > limits[joint].velocity_max:
                    raise InvalidRequest(f'speed {speed:.4f} exceeds {joint} velocity_max '
                                         f'{limits[joint].velocity_max:.4f}')
            for joint in device.joint_names:
                client.run('CFG_SetGeneralSpd', device.axis(joint), math.degrees(speed))
        device.programs.leave()
        client.run('PRST_GoToPreset', index)
        device.report_targets(self.positions(record))
        return f'moving to device preset {index} ({record.name or "unnamed"})'

    def list(self) -> list[tuple[int, str, dict[str, float]]]:
        client = self.device.client
        found = []
        for index in client.preset_indices():
            record = client.get_preset(index)
            found.append((index, record.name, self.positions(record)))
        return found

    def clear(self, index: int | None) -> str:
        client = self.device.client
        if index is None:
            client.run('PRST_ClearAll')
            return 'all device presets cleared'
        self._check_index(index)
        client.run('PRST_ClearSinglePreset', index)
        return f'device preset {index} cleared'


class CaptureScans(DeviceScans):
    """The device's zigzag, snake and square scans (SCN_*); limits in motor degrees."""

    patterns = tuple(sorted(SCAN_COMMANDS))
    #: ``CaptureDevice.stop(None)`` ends with SCN_StopScan: the core's whole stop is one
    stopped_by_device_stop = True

    def __init__(self, device: CaptureDevice) -> None:
        self.device = device

    def start(self, request: ScanRequest) -> str:
        """The core's scan-request check, then what the device adds: yaw and pitch are axes
        1 and 2, at most 255 rows; limits go out in motor degrees."""
        device = self.device
        config = _attached_config(device)
        pan, tilt = check_scan(request, scan_joints(config), config.limits,
                               self.patterns, 'the Capture device')
        if device.axis(pan) != 1 or device.axis(tilt) != 2:
            raise ScanError(f'device scans move yaw (axis 1) and pitch (axis 2); map the scan '
                            f'joints {pan} and {tilt} to axis_ids 1 and 2')
        steps = math.floor((request.tilt_max - request.tilt_min) / request.tilt_step + 1e-9)
        if steps > 255:
            raise ScanError(f'{steps} rows exceed the device maximum 255; increase tilt_step')
        gear = device.settings.gear

        def motor(joint: str, value: float) -> float:
            return device.to_device(joint, value) * gear[joint]

        yaw = sorted((motor(pan, request.pan_min), motor(pan, request.pan_max)))
        pitch_min = min(motor(tilt, request.tilt_min), motor(tilt, request.tilt_max))
        device.programs.leave()
        device.client.configure_scan(yaw[0], yaw[1], pitch_min, steps,
                                     math.degrees(request.tilt_step) * abs(gear[tilt]),
                                     math.degrees(request.speed) * abs(gear[pan]))
        device.client.start_scan(request.pattern)
        device.programs.scanning = True
        device.expire_status()
        return (f'device {request.pattern} scan started: yaw {yaw[0]:.2f}..{yaw[1]:.2f} deg, '
                f'{steps} step(s) of {math.degrees(request.tilt_step):.2f} deg')

    def stop(self) -> None:
        """The device's whole stop (``CaptureDevice.stop``): SCN_StopScan "stops both
        motors immediately" (4.3.9), and it goes out after the axes' own stop, so that
        the axes are told to stop whatever the scan stop's answer (up to 500 ms late) is.
        A refusal of SCN_StopScan fails it only while the driver knows of a device scan."""
        if self.device.client.connected:
            self.device.stop(None)
        self.device.programs.scanning = False


#: the pose source of the position and heading the user inserted on the device (4.4.21-27)
INSERTED_SOURCE = 'inserted position (GPS_GetInsertedLLA, override flag set)'


class CaptureGeolocation(Geolocation):
    """Where the pedestal stands and faces, as the controller knows it.

    With the 'Override GPS' flag (GPS_GetOvdPosGPS 1) the controller aims from the
    position and heading the user inserted (GPS_GetInsertedLLA, GPS_GetInsertedHeading):
    the whole pose, surveyed, so it does not age. Otherwise from its GPS: the heading
    (GPS_GetHeading while GPS_HeadingReady) is usable, but the position has no altitude
    (GPS_GetAltitude has no established opcode, see the README), so the position is
    missing and ~/look_at_geo names what to do: site_position, or insert the position.
    """

    def __init__(self, device: CaptureDevice) -> None:
        self.device = device

    def pose(self) -> geodesy.DevicePose:
        client = self.device.client
        if client.request('GPS_GetOvdPosGPS'):
            point = client.request('GPS_GetInsertedLLA')
            heading = client.request('GPS_GetInsertedHeading')
            return geodesy.DevicePose(
                geodesy.PositionFix(
                    geodesy.GeoPoint(point.latitude, point.longitude, point.altitude),
                    INSERTED_SOURCE),
                geodesy.OrientationFix(geodesy.Attitude.from_heading(math.radians(heading)),
                                       'inserted heading (GPS_GetInsertedHeading)'))
        if not self.device.functions.has_gps:
            reason = ('no GPS (GPS_isConnectedGPS 0) and no inserted position (override flag '
                      '0)')
            return geodesy.DevicePose(missing={'position': reason, 'orientation': reason})
        missing: dict[str, str] = {}
        fix = client.gps_fix()
        if fix is None or not fix[0]:
            missing['position'] = 'no GPS fix (GPS_PositionReady 0)'
        else:
            missing['position'] = (
                'the GPS gives no altitude (GPS_GetAltitude has no established opcode); or '
                'insert the position on the pedestal (GPS_SetInsertedLLA, '
                'GPS_SetInsertedHeading, GPS_SetOvdPosGPS 1)')
        heading = self.device.functions.gps_heading()
        orientation = None
        if heading is None:
            missing['orientation'] = 'no valid GPS heading (GPS_HeadingReady 0)'
        else:
            orientation = geodesy.OrientationFix(geodesy.Attitude.from_heading(heading),
                                                 'GPS heading', stamp=time.time())
        return geodesy.DevicePose(None, orientation, missing)


class CaptureTargetPointing(TargetPointing):
    """GPS_SetTargetLLA + GPS_GoToTarget on ``gps_target_slot`` (4.4.10-11): the pedestal
    aims itself from the pose it holds, like its presets and scans."""

    def __init__(self, device: CaptureDevice) -> None:
        self.device = device

    def refusal(self, pose: geodesy.GeoPose, speed: float) -> str | None:
        if pose.position.source != INSERTED_SOURCE:
            return 'the pedestal aims from its inserted position only'
        if speed > 0.0:
            return 'GPS_GoToTarget takes no speed (it moves at the axes\' general speed)'
        return None

    def point_at(self, target: geodesy.GeoPoint) -> str:
        device = self.device
        slot = device.settings.gps_target_slot
        device.programs.leave()
        device.client.goto_lla(slot, GeoPoint(target.longitude, target.latitude,
                                               target.altitude))
        return f'GPS_SetTargetLLA + GPS_GoToTarget on target {slot}'
