"""The Capture pedestal's extras in SI units (no ROS): IMU, GPS, rangefinder, video
tracker, digital I/O, preset and target loops, levelling, gyro drift and the raw
``~/command``. A mixin of :class:`~.device.CaptureDevice`, kept apart so the adapter's
core (link, poll, motion, refusals) reads in one sitting; the node's services call these
through ``controller.call``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

from gimbal_driver_common.config import scan_joints
from gimbal_driver_common.device import AxisStateCode, DeviceProcedure, ProcedureProgress
from gimbal_driver_common.errors import DeviceRefused, InvalidRequest

from .client import CaptureClient
from .command_text import (
    ALLOWED_MOTION,
    DEDICATED,
    JOINT_MOTION,
    OPT_IN,
    format_result,
    parse_arguments,
)
from .device_requests import TrackingState
from .errors import REQUEST_ERRORS, NotSupported
from .protocol import COMMANDS, GeoPoint, ProtocolError, Safety
from .protocol import command as lookup_command
from .protocol.geometry import aim_at

if TYPE_CHECKING:
    from .device import CaptureSettings

T = TypeVar('T')

DIGITAL_IO_COUNT = 6  # COM_get/setDigitalIO: I/O 1..6 in the axis byte (4.6.17-18)
TRACKING_MODES = {'off': 0, 'manual': 1, 'auto': 2}  # VDT_setTrackingOn values (4.11.1)
IMU_ANGLE_BY_AXIS = {1: 'yaw', 2: 'pitch', 3: 'roll'}  # what IMU_Leveling levels per axis


@dataclass
class ImuReading:
    """IMU attitude (rad, REP-103: yaw counter-clockwise) and gyro rates (rad/s)."""

    roll: float
    pitch: float
    yaw: float
    rates: tuple[float, float, float]


@dataclass
class GpsFix:
    ready: bool
    latitude: float  # deg
    longitude: float  # deg
    altitude: float  # m, NaN while GPS_GetAltitude's opcode is not established


@dataclass
class LevelErrors:
    """Per joint, how far the IMU angle is from its levelling value (reported in degrees,
    as the device counts them)."""

    degrees: dict[str, float]

    def within(self, tolerance: float) -> bool:
        """All within ``tolerance`` rad."""
        return all(abs(math.radians(e)) <= tolerance for e in self.degrees.values())

    def progress(self) -> str:
        return ', '.join(f'{j}: {abs(e):.3f} deg from level' for j, e in self.degrees.items())

    def summary(self) -> str:
        return ', '.join(f'{j} ({abs(e):.3f} deg)' for j, e in self.degrees.items())


class CaptureProcedure(DeviceProcedure):
    """Levelling and the drift measurement share the IMU and run one at a time; a device
    program (scan, loop) keeps them from starting."""

    group = 'a levelling or drift compensation'

    def __init__(self, device: CaptureFunctions) -> None:
        self.device = device

    def busy(self) -> str | None:
        return self.device.program_running()


class Levelling(CaptureProcedure):
    """IMU_Leveling (4.5.11): the controller turns the joints until the IMU reads its
    levelling values; done once every angle is within ``goal_tolerance`` and the axes
    rest, failed after ``move_timeout``."""

    name = 'levelling'
    cancelled = 'levelling cancelled; axes stopped'
    superseded = 'levelling ended by a newer motion command, which now moves the axes'

    def __init__(self, device: CaptureFunctions, joints: Sequence[str]) -> None:
        super().__init__(device)
        self.joints = list(joints) or list(device.joint_names)
        self.timeout = device.config.move_timeout
        self.timed_out = f'not level within move_timeout {self.timeout:g} s'

    def start(self) -> None:
        self.device.start_leveling(self.joints)

    def poll(self, elapsed: float) -> ProcedureProgress:
        errors = self.device.level_errors(self.joints)
        done = errors.within(self.device.config.goal_tolerance)
        return ProcedureProgress(errors.progress(), 'levelled ' + errors.summary() if done
                                 else None)


class GyroDriftMeasurement(CaptureProcedure):
    """IMU_GyroDriftCompensation (4.5.28): the pedestal holds still for ``duration`` s
    while the controller measures the drift (the spec gives no duration), then the
    result is read; any motion meanwhile makes it untrusted."""

    name = 'the drift measurement'
    cancelled = ('drift measurement cancelled (the controller may still finish it; '
                 '~/reset_gyro_drift clears it)')
    hold_still = True
    period = 0.2

    def __init__(self, device: CaptureFunctions, joints: Sequence[str],
                 duration: float) -> None:
        super().__init__(device)
        self.requested_joints, self.duration = list(joints), duration

    def start(self) -> None:
        if self.requested_joints:
            raise InvalidRequest('the drift compensation takes no joint names (it measures '
                                 f'IMU sensor {self.device.settings.gyro_drift_sensor}, '
                                 'gyro_drift_sensor)')
        self.device.start_gyro_drift()

    def poll(self, elapsed: float) -> ProcedureProgress:
        if elapsed >= self.duration:
            return ProcedureProgress(result=self.device.gyro_drift_result())
        return ProcedureProgress(f'holding still while measuring the gyro drift: '
                                 f'{elapsed:.1f} of {self.duration:g} s')


class CaptureFunctions:
    """The device functions of :class:`~.device.CaptureDevice` (which provides
    ``client``, ``settings``, ``config`` and the refusals they use)."""

    client: CaptureClient
    settings: CaptureSettings

    def _sensor(self, flag: str, read: Callable[[], T]) -> T:
        """One sensor read for its topic. When the device does not answer one of its
        getters with data (:class:`NotSupported`, which says which and how), ``flag`` is
        cleared: the topic stops asking until the next connection."""
        try:
            return read()
        except NotSupported:
            setattr(self, flag, False)
            raise

    def imu(self) -> ImuReading:
        """IMU attitude and rates; device yaw counts clockwise 0..360, REP-103 yaw the
        other way, so yaw is negated."""
        values = self._sensor('has_imu', self.client.imu)
        return ImuReading(
            roll=math.radians(values['roll']), pitch=math.radians(values['pitch']),
            yaw=-math.radians(values['yaw']),
            rates=(math.radians(values['gyro_x']), math.radians(values['gyro_y']),
                   math.radians(values['gyro_z'])))

    def gps_fix(self) -> GpsFix | None:
        """The GPS fix; None (and ``has_gps`` cleared: the poll stops) once the device
        refused one of its getters."""
        fix = self.client.gps_fix()
        if fix is None:
            self.has_gps = False
            return None
        ready, latitude, longitude = fix
        return GpsFix(ready, latitude, longitude, self._gps_altitude())

    def _gps_altitude(self) -> float:
        """GPS altitude in m where GPS_GetAltitude's opcode is established, else NaN."""
        if 'GPS_GetAltitude' not in COMMANDS:
            return math.nan  # 4.4.4 prints no opcode: 0x0506..0x0509 all fit (README)
        try:
            return float(self.client.request('GPS_GetAltitude'))
        except REQUEST_ERRORS:
            return math.nan

    def gps_heading(self) -> float | None:
        """Compass heading in rad (clockwise from north), None while not valid."""
        ready, heading = self._sensor('has_heading', self.client.gps_heading)
        return math.radians(heading) if ready else None

    def range_m(self) -> float:
        """Laser range in m; +inf when the device reads 0 (no return, REP-117)."""
        # 4.17.11: 1 = current/last
        distance = self._sensor('ranging', lambda: self.client.poll('LRF_GetLRFDistance', 1))
        return float(distance) if distance > 0 else math.inf

    def tracking_state(self) -> TrackingState:
        try:
            return self._sensor('has_tracker', lambda: self.client.tracking_state(
                self.settings.tracker_camera))
        except NotSupported as exc:
            self.tracker_problem = str(exc)
            raise

    def digital_io(self) -> list[int]:
        """States of digital I/O 1..6 (1 = set)."""
        states = self._sensor('has_digital_io', lambda: self.client.digital_io(
            list(range(1, DIGITAL_IO_COUNT + 1))))
        return [int(states[n]) for n in sorted(states)]

    # ---------------------------------------------------------- extras
    def set_stabilization(self, on: bool) -> str:
        self.client.run('STB_StabilizationOn' if on else 'STB_StabilizationOff')
        self.expire_status()
        return f'stabilisation {"on" if on else "off"}'

    def set_emergency_stop(self, on: bool) -> str:
        self.client.run('MOT_SetEmgStopAxes', None, int(on))
        self.device_scanning = self.preset_looping = False
        self.expire_status()
        if on:
            return 'emergency stop set: all axes stopped, motion commands refused'
        return 'emergency stop cleared (the controller reset the axes to relative mode)'

    def set_ranging(self, on: bool) -> str:
        if not on:
            self.client.run('LRF_StopMeasurement')
            self.ranging = False
            return 'ranging off (LRF_StopMeasurement)'
        if not self.client.request('LRF_IsConnected'):
            raise DeviceRefused('no rangefinder connected (LRF_IsConnected 0); nothing sent')
        self.client.run('LRF_StartMeasurement')
        self.ranging = True
        return 'ranging on'

    @staticmethod
    def tracking_mode(text: str) -> str:
        mode = text.strip().lower()
        if mode not in TRACKING_MODES:
            raise InvalidRequest(f'tracking mode {text!r} unknown; use one of '
                                 f'{list(TRACKING_MODES)}')
        return mode

    def set_tracking(self, text: str) -> str:
        """VDT_setTrackingOn for ``tracker_camera``; manual/auto refuse on a drive that is
        off or faulted (the tracker drives pan and tilt) and end device programs first."""
        mode = self.tracking_mode(text)
        camera = self.settings.tracker_camera
        if not self.has_tracker:
            raise DeviceRefused(f'no video tracker on camera {camera}: {self.tracker_problem}')
        if mode != 'off':
            refusal = self.refusal(scan_joints(self.config))
            if refusal:
                raise DeviceRefused(refusal)
            self.leave_device_programs()
        self.client.set_tracking(camera, TRACKING_MODES[mode])
        state = self.client.tracking_state(camera)
        if mode == 'manual' and not state.active:
            raise DeviceRefused(f'camera {camera}: manual tracking did not start: no target '
                                'detected (VDT_isTargetDetected 0)')
        return (f'camera {camera}: tracking {mode} (active: {state.active}, target detected: '
                f'{state.target_detected})')

    def set_digital_output(self, number: int, on: bool) -> str:
        self.client.set_digital_output(number, on)
        return f'digital output {number} {"set (on)" if on else "reset (off)"}'

    def faulted_joints(self) -> list[str]:
        status = self.capabilities.status
        return [j for j in self.joint_names
                if status.axis_details(j).get('state') == AxisStateCode.FAULT]

    def set_power(self, on: bool) -> str:
        """MOT_AxisOn / MOT_AxisOff on every joint (stop the axes before switching off)."""
        for joint in self.joint_names:
            self.client.set_axis_power(self.axis(joint), on)
        self.expire_status()
        verb = 'on (MOT_AxisOn)' if on else 'off (MOT_AxisOff)'
        return f'drives {verb}: {", ".join(self.joint_names)}'

    def start_preset_loop(self) -> str:
        presets = self.capabilities.presets
        indices = self.client.preset_indices()
        if not indices:
            raise DeviceRefused('no device presets stored; set some with ~/set_preset')
        for index in indices:
            presets.checked_record(index)
        self.leave_device_programs()
        self.client.run('PRST_StartPresetLooping')
        self.preset_looping = True
        return f'looping over device presets {indices}'

    def stop_preset_loop(self) -> None:
        self.client.run('PRST_StopPresetLooping')
        self.preset_looping = False

    def target_pose(self, target: GeoPoint) -> dict[str, float]:
        """Joint positions (rad) the device takes to look at ``target``, from the GPS or
        the inserted position and heading (what GPS_GoToTarget uses)."""
        client = self.client
        if client.request('GPS_GetOvdPosGPS'):
            origin = client.request('GPS_GetInsertedLLA')
            heading = client.request('GPS_GetInsertedHeading')
        else:
            fix = client.gps_fix()
            if fix is None:
                raise DeviceRefused('the device gives no GPS position (GPS getters refused)')
            _, latitude, longitude = fix
            origin = GeoPoint(longitude, latitude, target.altitude)
            heading = client.request('GPS_GetHeading')
        angles = aim_at(origin, heading, target)
        return {joint: self.from_device(joint, degrees)
                for joint, degrees in zip(self.joint_names[:2], angles, strict=False)}

    def goto_lla(self, latitude: float, longitude: float, altitude: float) -> dict[str, float]:
        """Aim at a geographic point: limit-check the pose the device will take, then
        GPS_SetTargetLLA + GPS_GoToTarget on ``gps_target_slot``; returns that pose."""
        for value, label, bound in ((latitude, 'latitude', 90.0),
                                    (longitude, 'longitude', 180.0)):
            if not math.isfinite(value) or abs(value) > bound:
                raise InvalidRequest(f'{label} {value} outside +-{bound}')
        target = GeoPoint(longitude, latitude, altitude if math.isfinite(altitude) else 0.0)
        pose = self.target_pose(target)
        self.check_pose(pose, f'the pose for lat {latitude:.6f} lon {longitude:.6f}')
        self.leave_device_programs()
        self.client.goto_lla(self.settings.gps_target_slot, target)
        self.report_targets(pose)
        return pose

    def start_target_loop(self) -> str:
        targets = self.client.stored_targets()
        if not targets:
            raise DeviceRefused('no GPS targets stored; set some with ~/command '
                                'GPS_SetTargetLLA')
        for number, point in targets.items():
            self.check_pose(self.target_pose(point),
                            f'target {number} (lat {point.latitude:.6f} lon '
                            f'{point.longitude:.6f})')
        self.leave_device_programs()
        self.client.run('GPS_StartTargetLooping')
        self.target_looping = True
        return f'looping over GPS targets {sorted(targets)}'

    def stop_target_loop(self) -> None:
        self.client.run('GPS_StopTargetLooping')
        self.target_looping = False

    def reset_gyro_drift(self) -> str:
        if not self.has_imu:
            raise DeviceRefused('the controller reports no IMU (IMU_IsReadyImu)')
        sensor = self.settings.gyro_drift_sensor
        self.client.run('IMU_ResetGyroDriftCompensation', sensor)
        return f'gyro drift compensation of IMU sensor {sensor} reset to 0'

    def levelling(self, joints: Sequence[str]) -> Levelling:
        """The ~/level procedure for ``joints`` (none: every joint), for the core's
        guarded policy (``guarded.GuardedProcedures``)."""
        return Levelling(self, joints)

    def gyro_drift_measurement(self, joints: Sequence[str], duration: float
                               ) -> GyroDriftMeasurement:
        """The drift measurement procedure; ``joints`` must be empty (it names none)."""
        return GyroDriftMeasurement(self, joints, duration)

    def level_errors(self, joints: Sequence[str]) -> LevelErrors:
        """Per joint: the angle between the IMU and its levelling value."""
        imu = self.client.imu()
        errors = {}
        for joint in joints:
            axis = self.axis(joint)
            level = self.client.request('IMU_getLevelingValue', axis)
            error = level - imu[IMU_ANGLE_BY_AXIS[axis]]
            errors[joint] = (error + 180.0) % 360.0 - 180.0  # yaw is 0..360
        return LevelErrors(errors)

    def start_leveling(self, joints: Sequence[str]) -> None:
        """IMU_Leveling (4.5.11) per joint, after checking the pose it ends at (current
        position + IMU angle error) against the limits."""
        unknown = [j for j in joints if j not in self.settings.axis]
        if unknown:
            raise InvalidRequest(f'unknown joint(s) {unknown}; this device has '
                                 f'{self.joint_names}')
        if not self.has_imu:
            raise DeviceRefused('levelling needs an IMU on the load; the controller reports '
                                'none (IMU_IsReadyImu)')
        refusal = self.refusal(joints)
        if refusal:
            raise DeviceRefused(refusal)
        errors = self.level_errors(joints).degrees
        targets = {j: self.from_device(j, self.client.request('MOT_GetLoadPosition',
                                                               self.axis(j)) + errors[j])
                   for j in joints}
        self.check_pose(targets, 'the levelled pose')
        self.leave_device_programs()
        for joint in joints:
            self.client.run('IMU_Leveling', self.axis(joint))
        self.report_targets(targets)

    def start_gyro_drift(self) -> None:
        """IMU_GyroDriftCompensation on ``gyro_drift_sensor``."""
        if not self.has_imu:
            raise DeviceRefused('the controller reports no IMU (IMU_IsReadyImu)')
        refusal = self.refusal(self.joint_names)
        if refusal:
            raise DeviceRefused(refusal)
        self.client.run('IMU_GyroDriftCompensation', self.settings.gyro_drift_sensor)

    def gyro_drift_result(self) -> str:
        """The drift ``gyro_drift_sensor`` measured, in deg/s (as the device reports) and
        rad/s."""
        sensor = self.settings.gyro_drift_sensor
        drift = self.client.request('IMU_GetGyroDrift', sensor)
        return (f'gyro drift of IMU sensor {sensor}: {drift:.5f} deg/s '
                f'({math.radians(drift):.6f} rad/s), compensated by the controller')

    def command(self, name: str, axis: int, arguments: Sequence[str]) -> tuple[str, list[str]]:
        """Run any in-scope table entry by name (``~/command``); returns (message, results).

        Motion entries point to their limit-checked interface; entries that write memory,
        reboot or change the network need their opt-in; arguments and axis are checked
        before anything is sent.
        """
        try:
            cmd = lookup_command(name.strip())
        except ProtocolError as exc:  # unknown, or opcode not established
            raise InvalidRequest(str(exc)) from None
        if cmd.safety is Safety.MOTION and cmd.name not in ALLOWED_MOTION:
            where = DEDICATED.get(cmd.name, 'the dedicated interface')
            raise InvalidRequest(f"{cmd.name} moves the axes without the driver's limit "
                                 f'checks; use {where}')
        opt_in = OPT_IN.get(cmd.safety)
        if opt_in and not getattr(self.settings, opt_in):
            raise DeviceRefused(f'{cmd.name} is a {cmd.safety.value} command; set the '
                                f'parameter {opt_in}:=true to allow it')
        value = parse_arguments(cmd.arg, list(arguments))
        if cmd.name in JOINT_MOTION and value != 0:  # 0 switches tracking/sync off
            refusal = self.refusal(self.joint_names)
            if refusal:
                raise DeviceRefused(f'{cmd.name} refused, nothing sent: {refusal}')
        target_axis = axis if (cmd.axis.low != cmd.axis.high or axis) else None
        try:
            cmd.frame(target_axis, value, self.settings.group_id)  # checks, nothing sent
        except ProtocolError as exc:
            raise InvalidRequest(str(exc)) from None
        # VDT_* take the camera index as `axis`; the codec puts it in the group byte (4.11)
        result = self.client.run(cmd.name, target_axis, value)
        results = format_result(cmd.name, result) if cmd.replies_with_data else []
        self.expire_status()
        if results:
            return f'{cmd.name}: ' + ', '.join(results), results
        return f'{cmd.name}: ACK', results
