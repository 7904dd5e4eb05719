"""Capture simulator: the command handlers longer than one row of the table."""

from __future__ import annotations

import threading
from typing import SupportsFloat

from ..protocol import Frame, GeoPoint, PresetRecord, ReplyCode
from ..protocol import registers as reg
from ..protocol.geometry import aim_at
from .axis import DRIFT_MEASURE_TIME, AxisModel, RequestRejected, ScanState


def _error_text(model: CommandHandlers, bit: int, text: str) -> str:
    return text if model._system_register() & (1 << bit) else ''


class CommandHandlers:
    """The handlers of :data:`~.table.HANDLERS` longer than one row; a base of
    :class:`~.model.PedestalModel`, whose state they read and change."""

    # The model's state the handlers use (PedestalModel.__init__ sets each).
    lock: threading.RLock
    axes: dict[int, AxisModel]
    emergency_stop: bool
    gear_ratio: float
    gps_present: bool
    scan: ScanState | None
    scan_params: dict[str, float]
    preset_looping: list[int] | None
    target_looping: list[int] | None
    gps_position: GeoPoint
    gps_heading: float
    gps_fix: bool
    inserted_position: GeoPoint
    inserted_heading: float
    override_gps: bool
    tracker_present: bool
    tracker_mode: dict[int, int]
    detected_targets: dict[int, list[tuple[int, int]]]
    gyro_drift: dict[int, float]
    drift_measuring: dict[int, float]
    stabilization: bool
    imu_present: bool
    digital_io_present: bool
    presets: dict[int, PresetRecord]
    targets: dict[int, GeoPoint]
    stored: dict[tuple[str, int], object]
    csr_latched: int
    protocol_error: str
    _loop_wait_until: float

    def _axis(self, frame: Frame) -> AxisModel:
        axis = self.axes.get(frame.axis)
        if axis is None:
            raise RequestRejected(ReplyCode.INVALID_COMMAND,
                                  'Axis not exist in the system' if frame.axis else
                                  'Invalid Axis 0 in motor command')
        return axis

    def _goto_preset(self, index: int) -> None:
        record = self.presets.get(index, PresetRecord(''))
        for number, axis in self.axes.items():
            self._move_to(axis, record.angles[number - 1], axis.general_speed)

    def _move_to(self, axis: AxisModel, target: float, speed: float) -> None:
        axis.speed_mode = False
        axis.jog_velocity = 0.0
        axis.speed = speed
        axis.target = target

    def _motion_allowed(self, axis: AxisModel | None = None) -> None:
        if self.emergency_stop:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Emergency stop flag is set')
        if axis is not None and axis.faulted:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'Axis in fault: reset faults')
        if axis is not None and axis.homing:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Command not valid while homing')

    def _scan_waypoints(self, pattern: str) -> list[tuple[float, float]]:
        p = self.scan_params
        y0, y1, p0 = p['yaw_min'], p['yaw_max'], p['pitch_min']
        steps, height = max(int(p['steps']), 0), p['step_height']
        points = [(y0, p0)]
        if pattern == 'zigzag':
            # 4.3: diagonal runs to (YawMax, +StepHeight), back to YawMin, NumSteps times.
            for i in range(1, steps + 1):
                points.append((y1 if i % 2 else y0, p0 + i * height))
            if steps == 0:
                points.append((y1, p0))
        elif pattern == 'snake':
            for i in range(steps + 1):
                row = p0 + i * height
                if i:
                    points.append((points[-1][0], row))
                points.append((y1 if i % 2 == 0 else y0, row))
        else:  # square: rectangles shrinking inward by StepHeight
            top = p0 + max(steps, 1) * height
            lo_y, hi_y, lo_p, hi_p = y0, y1, p0, top
            points = []
            while lo_y <= hi_y and lo_p <= hi_p and len(points) < 400:
                points += [(lo_y, lo_p), (hi_y, lo_p), (hi_y, hi_p), (lo_y, hi_p)]
                lo_y, hi_y, lo_p, hi_p = lo_y + height, hi_y - height, lo_p + height, hi_p - height
                if height <= 0:
                    break
        # scan limits are motor positions (4.3.1 remark); the model keeps load degrees
        return [(y / self.gear_ratio, q / self.gear_ratio) for y, q in points]

    def _tracking_active(self, camera: int) -> bool:
        """4.11.1: manual and automatic tracking run only while a target is detected."""
        return self.tracker_mode[camera] in (1, 2) and bool(self.detected_targets[camera])

    # ------------------------------------------------ handlers too long for one table row
    # (the table itself, HANDLERS in ``table``, has a row for every command executed)
    def _connect(self, frame, arg, session):
        session.connected = True
        for axis in self.axes.values():  # 4.6.2: axes on, position mode, relative, speed 0
            axis.axis_on, axis.speed_mode, axis.relative, axis.speed = True, False, True, 0.0

    def _disconnect(self, frame, arg, session):
        session.connected = False
        self.scan = None
        for axis in self.axes.values():
            axis.halt()
            axis.axis_on, axis.speed_mode, axis.relative = False, False, True

    def _system_state(self, frame, arg, session):
        value = 0
        if self.stabilization:
            value |= reg.SYS_STABILIZATION
        if self.scan is not None:
            value |= reg.SYS_SCANNING
        if self.preset_looping:
            value |= reg.SYS_PRESET_LOOPING
        if any(self._tracking_active(camera) for camera in self.tracker_mode):
            value |= 1 << 1  # SYS bit 1: tracking active
        if self.target_looping:
            value |= 1 << 4  # SYS bit 4: target looping active
        return value

    def _system_register(self, frame=None, arg=None, session=None):
        value = self.csr_latched
        if any(a.faulted for a in self.axes.values()):
            value |= 1 << 0
        if any(a.homing for a in self.axes.values()):
            value |= reg.CSR_HOMING_NOT_COMPLETED
        return value

    def _clear_errors(self, frame, arg, session):
        self.csr_latched = 0
        self.protocol_error = ''

    def _driver_error_string(self, frame, arg, session):
        bitmap = sum(1 << (n - 1) for n, a in self.axes.items() if a.faulted)
        return _error_text(self, 0, f'No communication with axes (bitmap): 0x{bitmap:02X}')

    # --- MOT motion
    def _set_acceleration(self, frame, arg, session):
        if arg <= 0:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid input')
        self._axis(frame).acceleration = arg

    def _speed_mode(self, frame, arg, session):
        axis = self._axis(frame)
        axis.speed_mode = True
        axis.target = None

    def _position_mode(self, frame, arg, session):
        axis = self._axis(frame)
        axis.speed_mode = False
        axis.jog_velocity = 0.0

    def _update(self, frame, arg, session):
        axis = self._axis(frame)
        if axis.speed_mode and axis.speed == 0.0:
            axis.target, axis.jog_velocity = None, 0.0  # sim: a stop is always accepted
            return
        self._motion_allowed(axis)
        if not axis.axis_on:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'Axis is off')
        self.preset_looping = None
        self.target_looping = None
        if axis.speed_mode:
            axis.target, axis.jog_velocity = None, axis.speed
            return
        if axis.pending_position is None:
            return  # nothing to execute; the controller keeps the last profile
        goal = axis.pending_position + (axis.position if axis.relative else 0.0)
        axis.pending_position = None
        axis.target = goal

    def _homing(self, frame, arg, session):
        axis = self._axis(frame)
        self._motion_allowed(axis)
        axis.target, axis.jog_velocity, axis.homing, axis.homed = None, 0.0, True, False

    def _axis_on(self, frame, arg, session):
        axis = self._axis(frame)
        if axis.faulted:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'Axis in fault: reset faults')
        axis.axis_on = True

    def _axis_off(self, frame, arg, session):
        axis = self._axis(frame)
        axis.axis_on = False
        axis.velocity = 0.0  # 4.2.12: stops; the buffered target resumes on AxisOn

    def _axis_reset(self, frame, arg, session):
        axis = self._axis(frame)
        axis.mer_latched = axis.der_latched = 0
        axis.halt()
        axis.homing, axis.homed = True, False

    def _reset_faults(self, frame, arg, session):
        axis = self._axis(frame)
        if axis.mer_latched:
            axis.axis_on = False  # sim: a cleared fault leaves the drive off until AxisOn
        axis.mer_latched = axis.der_latched = 0

    def _set_actual_position(self, frame, arg, session):
        axis = self._axis(frame)
        axis.halt()
        axis.position = arg / self.gear_ratio

    def _emergency_stop(self, frame, arg, session):
        self.emergency_stop = bool(arg)
        if self.emergency_stop:
            self.scan = None
            self.preset_looping = None
            self.target_looping = None
            for axis in self.axes.values():
                axis.halt()
        else:  # 4.2.20: profiles reset to relative position mode
            for axis in self.axes.values():
                axis.speed_mode, axis.relative = False, True

    # --- software limits
    def _set_negative_limit(self, frame, arg, session):
        axis = self._axis(frame)
        if arg >= axis.swls_pos:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid input')
        axis.swls_neg = arg

    def _set_positive_limit(self, frame, arg, session):
        axis = self._axis(frame)
        if arg <= axis.swls_neg:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid input')
        axis.swls_pos = arg

    def _activate_limits(self, frame, arg, session):
        axis = self._axis(frame)
        if arg and not axis.swls_neg <= axis.position <= axis.swls_pos:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'Position outside the SWLS range')
        axis.swls_active = bool(arg)

    # --- scans
    def _stop_scan(self, frame, arg, session):
        if self.scan is not None:
            self.scan = None
            for axis in self.axes.values():
                axis.halt()

    def _start_scan(self, pattern: str) -> None:
        self._motion_allowed()
        if self.scan_params['speed'] <= 0:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'Scan speed is 0')
        for axis in list(self.axes.values())[:2]:
            self._motion_allowed(axis)
            axis.stop()
            axis.speed_mode = False
        self.preset_looping = None
        self.target_looping = None
        self.scan = ScanState(self._scan_waypoints(pattern))

    # --- presets
    def _goto_preset_request(self, frame, arg, session):
        self._motion_allowed()
        if frame.axis not in self.presets:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'Preset not exist')
        for axis in self.axes.values():
            self._motion_allowed(axis)
        self.scan = None
        self.preset_looping = None
        self.target_looping = None
        self._goto_preset(frame.axis)

    def _start_preset_looping(self, frame, arg, session):
        self._motion_allowed()
        if not self.presets:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'No presets stored')
        self.scan = None
        self.preset_looping = sorted(self.presets)
        self._loop_wait_until = 0.0

    def _set_general_speed(self, frame, arg, session):
        if arg < 0:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid input')
        self._axis(frame).general_speed = arg

    # --- stabilisation
    def _stabilization_on(self, frame, arg, session):
        if not self.imu_present:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid command for Manual system')
        self.stabilization = True

    def _stabilization_off(self, frame, arg, session):
        self.stabilization = False
        for axis in self.axes.values():  # 4.8.2: speed/acc/position 0, relative position mode
            axis.stop()
            axis.speed_mode, axis.relative, axis.speed = False, True, 0.0

    # --- laser rangefinder (sim: a target 850 m away while measuring)
    def _lrf_distance(self, frame, arg, session):
        return 850.0 + 10.0 * (frame.axis - 1) if self.stored.get(('LRF_measuring', 0)) else 0.0

    def _target_distance(self, frame, arg, session):
        if self.stored.get(('LRF_distancesource', 0)):
            return self._lrf_distance(Frame(0, 1, 0x030A), None, session)
        return self.stored.get(('LRF_manualdistance', 0), 0.0)

    # --- GPS and targets
    def _system_position(self) -> tuple[GeoPoint, float]:
        if self.override_gps:
            return self.inserted_position, self.inserted_heading
        return self.gps_position, self.gps_heading

    def set_gps_from_console(self, args: list[str]) -> None:
        """`gps LAT LON ALT HEADING` or `gps nofix` (GPS_PositionReady/HeadingReady 0)."""
        with self.lock:
            if args == ['nofix']:
                self.gps_fix = False
                return
            latitude, longitude, altitude, heading = (float(a) for a in args)
            self.gps_position = GeoPoint(longitude, latitude, altitude)
            self.gps_heading, self.gps_fix = heading % 360.0, True

    def set_inserted_from_console(self, args: list[str]) -> None:
        """`inserted LAT LON ALT HEADING` (and the override flag on) or `inserted off`."""
        with self.lock:
            if args == ['off']:
                self.override_gps = False
                return
            latitude, longitude, altitude, heading = (float(a) for a in args)
            self.inserted_position = GeoPoint(longitude, latitude, altitude)
            self.inserted_heading, self.override_gps = heading % 360.0, True

    def _go_to_target(self, frame, arg, session):
        self._motion_allowed()
        target = self.targets.get(frame.axis)
        if target is None:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'Target not exist')
        if not self.gps_present and not self.override_gps:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'GPS commands not available')
        azimuth, elevation = aim_at(*self._system_position(), target)
        self.scan = None
        self._move_to(self.axes[1], azimuth, self.axes[1].general_speed)
        self._move_to(self.axes[2], elevation, self.axes[2].general_speed)

    def _start_target_looping(self, frame, arg, session):
        self._motion_allowed()
        if not self.targets:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'No targets stored')
        self.scan = None
        self.preset_looping = None
        self.target_looping = sorted(self.targets)
        self._loop_wait_until = 0.0

    # --- IMU levelling and gyro drift (sim: the IMU sits on the load)
    def _leveling(self, frame, arg, session):
        axis = self._axis(frame)
        self._motion_allowed(axis)
        if not axis.axis_on:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'Axis is off')
        stored = self.stored.get(('IMU_levelingvalue', frame.axis), 0.0)
        if not isinstance(stored, SupportsFloat):  # IMU_SetLevelingValue stores a float
            raise TypeError(f'levelling value {stored!r} is not a number')
        level = float(stored)
        # 4.5.11: the axis turns until the IMU angle reads the levelling value; the sim's
        # IMU yaw is heading + axis 1, pitch is axis 2 and roll is axis 3
        target = level - self.gps_heading if frame.axis == 1 else level
        self.scan = None
        self.preset_looping = self.target_looping = None
        self._move_to(axis, target, axis.general_speed)

    def _measure_drift(self, frame, arg, session):
        self.drift_measuring[frame.axis] = DRIFT_MEASURE_TIME  # the sensor in the axis byte

    def _reset_gyro_drift(self, frame, arg, session):
        self.drift_measuring.pop(frame.axis, None)
        self.gyro_drift[frame.axis] = 0.0

    # --- digital I/O (4.6.17-18); the console's 'dio' changes an input
    def _digital_io(self, frame, arg, session):
        if not self.digital_io_present:  # firmware before 2.22.0
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Opcode not Recognized')
        key = ('COM_digitalio', frame.axis)
        if arg is None:  # COM_getDigitalIO
            return self.stored.get(key, 0)
        self.stored[key] = int(arg)
        return None

    # --- video tracker (4.11): the camera index travels in the group byte
    def _camera(self, frame: Frame) -> int:
        if not self.tracker_present:
            raise RequestRejected(ReplyCode.VIDEO_TRACKER_UNAVAILABLE, 'No video tracker')
        if frame.group not in self.tracker_mode:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid camera index')
        return frame.group

    def _set_tracking(self, frame, arg, session):
        camera = self._camera(frame)
        if arg not in (0, 1, 2):
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid input')
        # 4.11.1: manual tracking starts only if a target is detected right now
        self.tracker_mode[camera] = 0 if arg == 1 and not self.detected_targets[camera] else arg
