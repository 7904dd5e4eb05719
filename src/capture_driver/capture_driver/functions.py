"""The Capture pedestal's extras in SI units (no ROS): IMU, GPS, rangefinder, video
tracker, digital I/O, preset and target loops, levelling, gyro drift and the raw
``~/command``. A part of :class:`~.device.CaptureDevice` (its ``functions`` attribute),
kept apart so the adapter's core (link, poll, motion, refusals) reads in one sitting; the
node's services call these through ``controller.call``.

The part owns what it knows of the extras (which units answered at connect, whether
ranging is on, why there is no tracker) and is handed the rest: the client, the settings
(joint map and units), the device's programs (:class:`~.programs.DevicePrograms`), the
status and preset capabilities, and the adapter's public motion checks
(:class:`MotionChecks`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, TypeVar

from gimbal_driver_common.config import ControllerConfig, scan_joints
from gimbal_driver_common.device import AxisStateCode
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
from .procedures import GyroDriftMeasurement, LevelErrors, Levelling
from .programs import DevicePrograms
from .protocol import COMMANDS, GeoPoint, ProtocolError, Safety
from .protocol import command as lookup_command
from .protocol.geometry import aim_at

if TYPE_CHECKING:
    from .capabilities import CapturePresets
    from .device import CaptureSettings
    from .status import CaptureStatus

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


class MotionChecks(Protocol):
    """What the functions use of the device adapter (:class:`~.device.CaptureDevice`):
    its public motion checks and the core's ``Device`` contract, nothing of its state."""

    def attached_config(self) -> ControllerConfig:
        """The controller's live configuration (limits, tolerances, timeouts)."""

    def refusal(self, joints: Sequence[str]) -> str | None:
        """Why these joints cannot move now (fault, drive off), or None."""

    def check_pose(self, pose: dict[str, float], what: str) -> None:
        """The core's pose check of a pose the device moves to by itself."""

    def report_targets(self, targets: dict[str, float]) -> None:
        """Tell the controller where a device-run motion goes."""

    def expire_status(self) -> None:
        """Read the registers on the next poll (after a command that changes them)."""


class CaptureFunctions:
    """The device functions of :class:`~.device.CaptureDevice`: a part handed what it uses.

    Its own state: which optional units answered at the last connect (``has_*``, set by
    :meth:`probe`, a flag cleared once the device stops answering that unit's getters),
    ``tracker_problem`` and ``ranging`` (on by ``~/set_ranging``, restarted on reconnect).
    """

    def __init__(self, client: CaptureClient, settings: CaptureSettings,
                 programs: DevicePrograms, status: CaptureStatus, presets: CapturePresets,
                 checks: MotionChecks) -> None:
        self.client = client
        self.settings = settings
        self.programs = programs
        self.status = status
        self.presets = presets
        self.checks = checks
        self.has_imu = self.has_gps = self.has_heading = False
        self.has_tracker = self.has_digital_io = False
        self.tracker_problem = ''
        self.ranging = False

    # ----------------------------------------------------------- units
    @property
    def joint_names(self) -> list[str]:
        return list(self.settings.joint_names)

    def axis(self, joint: str) -> int:
        return self.settings.axis[joint]

    def from_device(self, joint: str, degrees: float) -> float:
        return self.settings.from_device(joint, degrees)

    # ---------------------------------------------------------- connect
    def probe(self, log: Callable[[str], object]) -> None:
        """Which optional units answer, at each connect; ``optional()``: a device without a
        function answers 0xA6 once and is not asked again (a missing video tracker NACKs
        with 0x76). Ranging that was on before a reconnect is started again (the
        controller may have rebooted); ``log`` warns when that fails."""
        client = self.client
        self.has_imu = bool(client.optional('IMU_IsReadyImu'))
        self.has_gps = self.has_heading = bool(client.optional('GPS_isConnectedGPS'))
        if self.ranging:
            try:
                client.run('LRF_StartMeasurement')
            except REQUEST_ERRORS as exc:
                self.ranging = False
                log(f'ranging not restarted after reconnect: {exc}')
        # firmware before 2.22.0 has no digital I/O: polling it would latch protocol errors
        self.has_digital_io = client.optional('COM_getDigitalIO', 1) is not None
        camera = self.settings.tracker_camera
        self.has_tracker = client.optional('VDT_isTrackingOn', camera) is not None
        self.tracker_problem = '' if self.has_tracker else client.unsupported.get(
            'VDT_isTrackingOn', 'VDT_isTrackingOn refused or unanswered (no video tracker)')

    # ----------------------------------------------------------- sensors
    def _sensor(self, flag: str, read: Callable[[], T]) -> T:
        """One sensor read for its topic. When the device does not answer one of its
        getters with data (:class:`NotSupported`, which says which and how), ``flag`` (one
        of this part's ``has_*``/``ranging``) is cleared: the topic stops asking until the
        next connection."""
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
        self.checks.expire_status()
        return f'stabilisation {"on" if on else "off"}'

    def set_emergency_stop(self, on: bool) -> str:
        self.client.run('MOT_SetEmgStopAxes', None, int(on))
        self.programs.scanning = self.programs.preset_looping = False
        self.checks.expire_status()
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
            refusal = self.checks.refusal(scan_joints(self.checks.attached_config()))
            if refusal:
                raise DeviceRefused(refusal)
            self.programs.leave()
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
        status = self.status
        return [j for j in self.joint_names
                if status.axis_details(j).get('state') == AxisStateCode.FAULT]

    def set_power(self, on: bool) -> str:
        """MOT_AxisOn / MOT_AxisOff on every joint (stop the axes before switching off)."""
        for joint in self.joint_names:
            self.client.set_axis_power(self.axis(joint), on)
        self.checks.expire_status()
        verb = 'on (MOT_AxisOn)' if on else 'off (MOT_AxisOff)'
        return f'drives {verb}: {", ".join(self.joint_names)}'

    def start_preset_loop(self) -> str:
        presets = self.presets
        indices = self.client.preset_indices()
        if not indices:
            raise DeviceRefused('no device presets stored; set some with ~/set_preset')
        for index in indices:
            presets.checked_record(index)
        self.programs.leave()
        self.client.run('PRST_StartPresetLooping')
        self.programs.preset_looping = True
        return f'looping over device presets {indices}'

    def stop_preset_loop(self) -> None:
        self.client.run('PRST_StopPresetLooping')
        self.programs.preset_looping = False

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
        self.checks.check_pose(pose, f'the pose for lat {latitude:.6f} lon {longitude:.6f}')
        self.programs.leave()
        self.client.goto_lla(self.settings.gps_target_slot, target)
        self.checks.report_targets(pose)
        return pose

    def start_target_loop(self) -> str:
        targets = self.client.stored_targets()
        if not targets:
            raise DeviceRefused('no GPS targets stored; set some with ~/command '
                                'GPS_SetTargetLLA')
        for number, point in targets.items():
            self.checks.check_pose(self.target_pose(point),
                            f'target {number} (lat {point.latitude:.6f} lon '
                            f'{point.longitude:.6f})')
        self.programs.leave()
        self.client.run('GPS_StartTargetLooping')
        self.programs.target_looping = True
        return f'looping over GPS targets {sorted(targets)}'

    def stop_target_loop(self) -> None:
        self.client.run('GPS_StopTargetLooping')
        self.programs.target_looping = False

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
        refusal = self.checks.refusal(joints)
        if refusal:
            raise DeviceRefused(refusal)
        errors = self.level_errors(joints).degrees
        targets = {j: self.from_device(j, self.client.request('MOT_GetLoadPosition',
                                                               self.axis(j)) + errors[j])
                   for j in joints}
        self.checks.check_pose(targets, 'the levelled pose')
        self.programs.leave()
        for joint in joints:
            self.client.run('IMU_Leveling', self.axis(joint))
        self.checks.report_targets(targets)

    def start_gyro_drift(self) -> None:
        """IMU_GyroDriftCompensation on ``gyro_drift_sensor``."""
        if not self.has_imu:
            raise DeviceRefused('the controller reports no IMU (IMU_IsReadyImu)')
        refusal = self.checks.refusal(self.joint_names)
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
            refusal = self.checks.refusal(self.joint_names)
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
        self.checks.expire_status()
        if results:
            return f'{cmd.name}: ' + ', '.join(results), results
        return f'{cmd.name}: ACK', results
