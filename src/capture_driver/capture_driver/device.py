"""The Capture pedestal as a :class:`~gimbal_driver_common.device.Device` (no ROS).

:class:`CaptureDevice` wraps one :class:`~.client.CaptureClient` and speaks SI units and
REP-103 signs: every degree <-> radian conversion, the per-joint direction (Capture yaw
counts clockwise) and the gear ratio of the scan limits happen here and nowhere else. The
controller (``gimbal_driver_common.controller``) runs it: it opens and reopens the link,
polls :meth:`CaptureDevice.read`, sends moves, jogs and stops, and asks
:meth:`CaptureDevice.refusal` before motion. Homing, the device's preset slots (all of
them), its own scans and the register-based status are small capability objects; the
device's extras (IMU, GPS, rangefinder, video tracker, digital I/O, loops, levelling,
gyro drift, ``~/command``) are plain methods the node's services call through
``controller.call``.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

from gimbal_driver_common import geodesy
from gimbal_driver_common.config import scan_joints
from gimbal_driver_common.device import (
    AxisStateCode,
    Device,
    DeviceInfo,
    DevicePresets,
    DeviceScans,
    Geolocation,
    Homing,
    JointSample,
    Moves,
    PostedWrite,
    StatusReport,
    TargetPointing,
)
from gimbal_driver_common.diagnostics import ActiveFlag, Level, StatusPart
from gimbal_driver_common.errors import DeviceRefused, InvalidRequest, LinkError
from gimbal_driver_common.joint_command import check_positions
from gimbal_driver_common.scan import ScanError, ScanRequest, check_scan
from gimbal_driver_common.transport import ByteStream, SerialStream, TcpStream

from .client import (
    IDENTITY_GETTERS,
    REQUEST_ERRORS,
    SCAN_COMMANDS,
    CaptureClient,
    DeviceNack,
    Identity,
    NotConnected,
    NotSupported,
    TrackingState,
    WrongReply,
)
from .protocol import COMMANDS, DataType, GeoPoint, PresetRecord, ProtocolError, Safety
from .protocol import command as lookup_command
from .protocol.geometry import aim_at
from .protocol.registers import AXIS_REGISTERS, CSR, SYSTEM_REGISTERS, SYSTEM_STATE

LOG = logging.getLogger('capture_driver.device')

T = TypeVar('T')

#: what ``hardware_id``, diagnostics and ~/status say for an identity the device did not give
UNKNOWN = 'unknown'

MAX_PRESETS = 15
DIGITAL_IO_COUNT = 6  # COM_get/setDigitalIO: I/O 1..6 in the axis byte (4.6.17-18)
TRACKING_MODES = {'off': 0, 'manual': 1, 'auto': 2}  # VDT_setTrackingOn values (4.11.1)
IMU_ANGLE_BY_AXIS = {1: 'yaw', 2: 'pitch', 3: 'roll'}  # what IMU_Leveling levels per axis

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


@dataclass
class CaptureSettings:
    """What the adapter needs from the node's parameters; the node keeps it up to date
    for the run-time ones (speeds, acceleration, periods, slots)."""

    joint_names: list[str]
    axis_ids: list[int]
    joint_directions: list[float]
    gear_ratios: list[float]
    transport: str = 'tcp'
    host: str = '192.168.10.120'
    port: int = 4949
    serial_port: str = '/dev/ttyUSB0'
    baudrate: int = 115200
    group_id: int = 0
    request_timeout: float = 0.5
    keepalive_period: float = 0.5
    batch_reads: bool = True
    default_speed: float = 0.5  # rad/s
    acceleration: float = 3.0  # rad/s^2
    status_period: float = 0.5
    home_timeout: float = 120.0
    gps_target_slot: int = 15
    tracker_camera: int = 0
    gyro_drift_sensor: int = 2
    allow_nv_write: bool = False
    allow_reboot: bool = False
    allow_network_config: bool = False
    axis: dict[str, int] = field(init=False)
    direction: dict[str, float] = field(init=False)
    gear: dict[str, float] = field(init=False)

    def __post_init__(self) -> None:
        self.axis = dict(zip(self.joint_names, self.axis_ids, strict=True))
        self.direction = dict(zip(self.joint_names, self.joint_directions, strict=True))
        self.gear = dict(zip(self.joint_names, self.gear_ratios, strict=True))

    def link_description(self) -> str:
        if self.transport == 'tcp':
            return f'tcp://{self.host}:{self.port}'
        return f'serial://{self.serial_port}?baudrate={self.baudrate}'

    def open_stream(self) -> ByteStream:
        if self.transport == 'tcp':
            return TcpStream(self.host, self.port, connect_timeout=2.0)
        return SerialStream(self.serial_port, self.baudrate)


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


def axis_flags(registers: dict[str, int]) -> list[ActiveFlag]:
    """Active flags of one axis' polled registers (MER, DER, SRH, SRL, MSR, CMER, OPR),
    decoded from those the device reports: a register it does not answer is no flag (read
    as 0, SRL's active-low "axis_off" would refuse every move)."""
    return [a for r in AXIS_REGISTERS if r.name in registers for a in r.decode(registers[r.name])]


def system_flags(registers: dict[str, int]) -> list[ActiveFlag]:
    """Active flags of the system registers the device reports (CSR, SYS)."""
    return [a for r in SYSTEM_REGISTERS if r.name in registers
            for a in r.decode(registers[r.name])]


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
            parts = _split(args, 7)
            return PresetRecord(parts[0], tuple(float(a) for a in parts[1:]))
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


def hardware_id(ident: Identity, link: str) -> str:
    """capture-pn<part>-sn<serial>-hw<rev>-fw<firmware>, "unknown" for what the device did
    not give; without a serial number the link address (``@<link>``) keeps two such
    devices apart."""
    text = '-'.join(['capture', *(f'{key}{value or UNKNOWN}' for key, value in (
        ('pn', ident.part_number), ('sn', ident.serial_number), ('hw', ident.hardware),
        ('fw', ident.firmware)))])
    return text if ident.serial_number else f'{text}@{link}'


def device_info(ident: Identity, link: str) -> DeviceInfo:
    """The controller's DeviceInfo (~/status, diagnostics): "unknown" where not read."""
    firmware = (ident.firmware or UNKNOWN) + (f' (hw {ident.hardware})' if ident.hardware
                                              else '')
    return DeviceInfo(model=ident.part_number or f'Capture pedestal (part number {UNKNOWN})',
                      serial_number=ident.serial_number or UNKNOWN,
                      firmware_version=firmware, hardware_id=hardware_id(ident, link))


class CaptureDevice(Device):
    """One Capture controller in SI units; thread-safe (the client serialises requests)."""

    def __init__(self, settings: CaptureSettings) -> None:
        super().__init__()  # the controller attaches its config (live limits) and logger
        self.settings = settings
        self.client = CaptureClient(
            settings.open_stream, group=settings.group_id, timeout=settings.request_timeout,
            expect_greeting=settings.transport == 'tcp',
            keepalive_period=settings.keepalive_period, batch_reads=settings.batch_reads)
        self._status: dict[str, Any] = {}
        self._status_lock = threading.Lock()
        self._next_status = 0.0
        self._warned: dict[str, float] = {}
        self.has_imu = self.has_gps = self.has_tracker = self.has_digital_io = False
        self.has_heading = False
        self.tracker_problem = ''
        #: the identity the device gave at the last open (what it did not: ``problems``)
        self.identity = Identity()
        self.ranging = False
        self.device_scanning = self.preset_looping = self.target_looping = False
        self.capabilities.homing = CaptureHoming(self)
        self.capabilities.geolocation = CaptureGeolocation(self)
        self.capabilities.target_pointing = CaptureTargetPointing(self)
        self.capabilities.presets = CapturePresets(self)
        self.capabilities.scans = CaptureScans(self)
        self.capabilities.status = CaptureStatus(self)

    # ----------------------------------------------------------- units
    def to_device(self, joint: str, radians: float) -> float:
        """rad (REP-103) -> device degrees on this joint's axis."""
        return math.degrees(radians) * self.settings.direction[joint]

    def from_device(self, joint: str, degrees: float) -> float:
        """device degrees -> rad (REP-103)."""
        return math.radians(degrees * self.settings.direction[joint])

    def axis(self, joint: str) -> int:
        return self.settings.axis[joint]

    @property
    def joint_names(self) -> list[str]:
        return list(self.settings.joint_names)

    def _warn(self, key: str, message: str, period: float = 10.0) -> None:
        """Log a warning at most once per ``period`` s per key (repeated poll failures)."""
        now = time.monotonic()
        if now - self._warned.get(key, -math.inf) >= period:
            self._warned[key] = now
            self.log.warning(message)

    # ------------------------------------------------------------ link
    def open(self) -> DeviceInfo:
        """Connect and read what the device tells about itself, best effort: only the link
        and the handshake must work (the joint poll is the controller's first read); an
        identity getter or probe the device does not answer with data leaves "unknown" or
        "no", said once here and named in the diagnostics."""
        client = self.client
        client.connect()
        self.identity = ident = client.identity()
        if ident.problems:
            unread = [attr.replace('_', ' ') for attr, name in IDENTITY_GETTERS
                      if name in ident.problems]
            self.log.warning(f'identity: {", ".join(unread)} {UNKNOWN} ('
                             + '; '.join(f'{name}: {how}' for name, how in
                                         ident.problems.items()) + ')')
        self.has_imu = bool(client.optional('IMU_IsReadyImu'))
        self.has_gps = self.has_heading = bool(client.optional('GPS_isConnectedGPS'))
        self.device_scanning = bool(client.optional('SCN_IsScanOn'))
        self.preset_looping = self.target_looping = False
        self._probe_extras()
        self._next_status = 0.0
        client.start()
        self.log.info(
            f'Capture controller on {client.description}: IMU {"yes" if self.has_imu else "no"}'
            f', GPS {"yes" if self.has_gps else "no"}')
        return device_info(ident, self.settings.link_description())

    def _probe_extras(self) -> None:
        """Which optional units answer (a missing video tracker NACKs with 0x76); ranging
        that was on before a reconnect is started again (the controller may have rebooted)."""
        client = self.client
        if self.ranging:
            try:
                client.run('LRF_StartMeasurement')
            except REQUEST_ERRORS as exc:
                self.ranging = False
                self.log.warning(f'ranging not restarted after reconnect: {exc}')
        # firmware before 2.22.0 has no digital I/O: polling it would latch protocol errors
        # optional(): a device without the function answers 0xA6 once and is not asked again
        self.has_digital_io = client.optional('COM_getDigitalIO', 1) is not None
        camera = self.settings.tracker_camera
        self.has_tracker = client.optional('VDT_isTrackingOn', camera) is not None
        self.tracker_problem = '' if self.has_tracker else client.unsupported.get(
            'VDT_isTrackingOn', 'VDT_isTrackingOn refused or unanswered (no video tracker)')

    def close(self) -> None:
        self.client.stop()
        with self._status_lock:
            self._status = {}

    def link_healthy(self) -> bool:
        return self.client.connected

    def description(self) -> str:
        return self.settings.link_description()

    # ------------------------------------------------------------ poll
    def read(self) -> JointSample | None:
        """Load position and speed of every axis; registers every ``status_period``.

        ``moving`` stays empty: the speed read every cycle is the freshest motion signal
        (the SRL motion-complete bit is read only every ``status_period``), so the
        controller's one rule applies.
        """
        joints = self.joint_names
        try:
            # one write for every axis: see CaptureClient.read_many
            values = self.client.read_many([
                (name, self.axis(joint)) for joint in joints
                for name in ('MOT_GetLoadPosition', 'MOT_GetMotorSpeed')])
        except REQUEST_ERRORS as exc:  # an answer of the wrong kind too: the link stays
            self._warn('poll', f'poll skipped: {exc}', 5.0)
            return None
        positions = {joint: self.from_device(joint, values[2 * i])
                     for i, joint in enumerate(joints)}
        velocities = {joint: self.from_device(joint, values[2 * i + 1])
                      for i, joint in enumerate(joints)}
        stamp = time.time()
        if time.monotonic() >= self._next_status:
            self.refresh_status()
        with self._status_lock:
            currents = self._status.get('current', {})
        return JointSample(
            positions=positions, velocities=velocities, stamp=stamp,
            efforts={j: currents[j] for j in self.joint_names if j in currents})

    def refresh_status(self) -> None:
        """Registers, currents (A) and error strings, cached for diagnostics, ~/status and
        the axis refusals; also tells which device programs (scan, loops) run."""
        client = self.client
        self._next_status = time.monotonic() + self.settings.status_period
        status: dict[str, Any] = {'axes': {}, 'current': {}, 'problems': []}
        for joint in self.joint_names:
            axis = self.axis(joint)
            try:
                status['axes'][joint] = client.registers(axis)
                with contextlib.suppress(NotSupported):  # no effort in joint_states
                    status['current'][joint] = client.poll('MOT_GetMotorCurrent', axis) / 1000.0
            except REQUEST_ERRORS as exc:
                status['problems'].append(f'{joint}: {exc}')
        try:
            system = client.registers(None)
            status['system'] = system
            status['errors'] = client.error_strings(system.get('CSR', 0))
            with contextlib.suppress(NotSupported):
                status['emergency_stop'] = bool(client.poll('MOT_GetEmgStopAxes'))
        except REQUEST_ERRORS as exc:
            status['problems'].append(f'system: {exc}')
        status['refusals'] = {joint: self._axis_refusal(joint, registers)
                              for joint, registers in status['axes'].items()}
        sys_state = status.get('system', {}).get('SYS', 0)
        self.device_scanning = bool(sys_state & (1 << 2))
        self.preset_looping = bool(sys_state & (1 << 3))
        self.target_looping = bool(sys_state & (1 << 4))
        with self._status_lock:
            self._status = status

    def status_snapshot(self) -> dict[str, Any]:
        with self._status_lock:
            return self._status

    def expire_status(self) -> None:
        """Read the registers on the next poll (after a command that changes them)."""
        self._next_status = 0.0

    # ---------------------------------------------------------- motion
    def leave_device_programs(self) -> None:
        """A new motion command ends a device scan or preset/target loop first (4.3 refuses
        motor writes with 0xA6 while scanning)."""
        client = self.client
        if self.device_scanning:
            client.request('SCN_StopScan')
            self.device_scanning = False
        if self.preset_looping:
            client.request('PRST_StopPresetLooping')
            self.preset_looping = False
        if self.target_looping:
            client.request('GPS_StopTargetLooping')
            self.target_looping = False

    def move(self, moves: Moves) -> None:
        """Absolute moves; the whole set-up of every axis under one hold of the client's
        lock, so the poll does not interleave its reads."""
        with self.client.exclusive():
            self.leave_device_programs()
            for axis, (position, speed, acceleration) in self._axis_moves(moves).items():
                self.client.move_absolute(axis, position, speed, acceleration)

    def _axis_moves(self, moves: Moves) -> dict[int, tuple[float, float, float]]:
        """Joint moves in the client's terms: axis -> (position, speed, acceleration)."""
        acceleration = math.degrees(self.settings.acceleration)
        return {self.axis(joint): (self.to_device(joint, target),
                                   math.degrees(speed if speed else self.settings.default_speed),
                                   acceleration)
                for joint, (target, speed) in moves.items()}

    def post(self, moves: Moves, jogs: dict[str, float]) -> PostedWrite | None:
        """A stream move written at once when the axes are already set up for it (the
        client's ``post_moves``: SendPosition + MOT_Update per axis, two ACKs each, read
        by :meth:`settle`), so the joint_command callback writes it without waiting; not
        a jog, nor while a device program runs (a move ends it first, with requests that
        wait)."""
        if jogs or not moves or self.device_scanning or self.preset_looping \
                or self.target_looping:
            return None
        axis_moves = self._axis_moves(moves)
        if not self.client.post_moves(axis_moves):
            return None
        return PostedWrite(dict(moves), {}, replies=2 * len(axis_moves))

    def settle(self, posted: PostedWrite) -> bool:
        return self.client.finish_posted()

    def jog(self, velocities: dict[str, float]) -> None:
        with self.client.exclusive():
            self.leave_device_programs()
            for joint, velocity in velocities.items():
                if velocity == 0.0:
                    self.client.stop_axis(self.axis(joint))
                else:
                    self.client.jog(self.axis(joint), self.to_device(joint, velocity),
                                    math.degrees(self.settings.acceleration))

    def stop(self, joints: Sequence[str] | None = None) -> None:
        """None: scans, loops and every axis (SCN_StopScan, PRST_StopPresetLooping,
        GPS_StopTargetLooping, then speed 0 per axis); else those axes."""
        with self.client.exclusive():
            if joints is None:
                problems = self.client.stop_all([self.axis(j) for j in self.joint_names])
                self.device_scanning = self.preset_looping = self.target_looping = False
            else:
                problems = []
                for joint in joints:
                    try:
                        self.client.stop_axis(self.axis(joint))
                    except REQUEST_ERRORS as exc:
                        problems.append(str(exc))
        if problems:
            raise DeviceRefused('; '.join(problems))

    def reset_faults(self) -> str:
        """Per axis MOT_ResetFaults + MOT_AxisOn (4.10) and a stop, then ERR_ClearErrors;
        the answer quotes the device (its NACK and reason, or the axis state it reports
        afterwards), and fails while an axis is still off or faulted."""
        client = self.client
        for joint in self.joint_names:
            axis = self.axis(joint)
            try:
                client.reset_faults(axis)  # ResetFaults + AxisOn (4.10)
                client.stop_axis(axis)  # AxisOn resumes a buffered move (4.2.11)
            except REQUEST_ERRORS as exc:
                self.expire_status()
                raise DeviceRefused(f'{joint}: {exc}') from exc
        client.request('ERR_ClearErrors')
        self.refresh_status()  # motion checks see the new state at once
        still = self.refusal(self.joint_names)
        if still:
            raise DeviceRefused('the device ACKed MOT_ResetFaults and MOT_AxisOn, but ' + still)
        return ('device ACKed MOT_ResetFaults, MOT_AxisOn and ERR_ClearErrors; registers '
                'now show ' + ', '.join(f'{j} on, no fault' for j in self.joint_names))

    def refusal(self, joints: Sequence[str]) -> str | None:
        """Refuse motion on an axis whose last registers show a fault or the drive off.

        The device ACKs position commands to an axis that is off and then does not move;
        the registers polled every ``status_period`` say why, so the driver refuses first.
        Each reason is decoded once per register poll (:meth:`refresh_status`), not per
        command: every joint_command asks.
        """
        refusals = self.status_snapshot().get('refusals', {})
        reasons = [refusals[joint] for joint in joints if refusals.get(joint)]
        if not reasons:
            return None
        return '; '.join(reasons) + '; ~/reset_faults clears faults (MOT_ResetFaults + MOT_AxisOn)'

    @staticmethod
    def _axis_refusal(joint: str, registers: dict[str, int]) -> str | None:
        """Why one axis cannot move, from its registers (a fault, the drive off), or None."""
        active = axis_flags(registers)
        faults = sorted({a.key for a in active if a.flag.level >= Level.ERROR})
        if faults:
            return f'{joint} is faulted ({", ".join(faults)})'
        off = sorted({a.key for a in active if a.flag.name == 'axis_off'})
        if off:  # named after the registers that said so (SRL, CMER): only those answered
            return f'{joint} drive is off ({", ".join(off)}); switch it on with ~/enable'
        return None

    def program_running(self) -> str | None:
        """Why the device is busy with a motion program of its own (scan, loop), or None."""
        if self.device_scanning:
            return 'a scan is running; stop it with ~/stop_scan first'
        if self.preset_looping or self.target_looping:
            return 'a preset or target loop is running; stop it first'
        return None

    def check_pose(self, pose: dict[str, float], what: str) -> None:
        """The core's one pose check (unknown joint, outside the live limits) of a pose
        the device itself moves to, naming ``what`` (a preset, a target, ...)."""
        check_positions(pose, self.config.limits, what)

    # ----------------------------------------------------- sensors (SI)
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


class CaptureHoming(Homing):
    """MOT_Homing per axis; progress from SRL bit 8 (homing active) and the load position."""

    def __init__(self, device: CaptureDevice) -> None:
        self.device = device

    def home(self, joints: Sequence[str], report: Callable[[str], None],
             cancelled: threading.Event) -> str:
        device, client = self.device, self.device.client
        try:
            device.leave_device_programs()
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
        limits = device.config.limits
        if speed > 0:
            for joint in device.joint_names:
                if speed > limits[joint].velocity_max:
                    raise InvalidRequest(f'speed {speed:.4f} exceeds {joint} velocity_max '
                                         f'{limits[joint].velocity_max:.4f}')
            for joint in device.joint_names:
                client.run('CFG_SetGeneralSpd', device.axis(joint), math.degrees(speed))
        device.leave_device_programs()
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

    def __init__(self, device: CaptureDevice) -> None:
        self.device = device

    def start(self, request: ScanRequest) -> str:
        """The core's scan-request check, then what the device adds: yaw and pitch are axes
        1 and 2, at most 255 rows; limits go out in motor degrees."""
        device = self.device
        pan, tilt = check_scan(request, scan_joints(device.config), device.config.limits,
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
        device.leave_device_programs()
        device.client.configure_scan(yaw[0], yaw[1], pitch_min, steps,
                                     math.degrees(request.tilt_step) * abs(gear[tilt]),
                                     math.degrees(request.speed) * abs(gear[pan]))
        device.client.start_scan(request.pattern)
        device.device_scanning = True
        device.expire_status()
        return (f'device {request.pattern} scan started: yaw {yaw[0]:.2f}..{yaw[1]:.2f} deg, '
                f'{steps} step(s) of {math.degrees(request.tilt_step):.2f} deg')

    def stop(self) -> None:
        """SCN_StopScan. A refusal (or a reply of the wrong kind) while the driver knows of
        no device scan is not a failed stop: a controller without the scan functions
        refuses it, and ~/stop must stop its axes all the same (``device.stop`` follows)."""
        device = self.device
        if device.client.connected:
            try:
                device.client.request('SCN_StopScan')
            except (DeviceNack, WrongReply) as exc:
                if device.device_scanning:
                    raise
                LOG.debug('SCN_StopScan with no device scan known: %s', exc)
        device.device_scanning = False


class CaptureStatus(StatusReport):
    """Diagnostics and ~/status from the registers the last poll cached."""

    def __init__(self, device: CaptureDevice) -> None:
        self.device = device

    def parts(self) -> list[StatusPart]:
        device = self.device
        status = device.status_snapshot()
        if not status:
            return [StatusPart('device', Level.STALE, 'no register data yet')]
        parts = []
        client = device.client
        for joint in device.joint_names:
            registers = status['axes'].get(joint)
            if registers is None:
                parts.append(StatusPart(joint, Level.STALE, 'registers unavailable'))
                continue
            values = [(f'{name}_raw', f'0x{value:04X}') for name, value in registers.items()]
            if not registers:
                values.append(('registers', 'the device reports none (see device status)'))
            current = status['current'].get(joint)
            if current is not None:
                values.append(('current_A', f'{current:.3f}'))
            values.append(('axis_id', str(device.axis(joint))))
            parts.append(StatusPart.from_flags(joint, axis_flags(registers), values))
        system = status.get('system', {})
        active = system_flags(system)
        values = [(f'{name}_raw', f'0x{value:04X}') for name, value in system.items()]
        values += [(f'error.{name}', text) for name, text in status.get('errors', {}).items()
                   if text]
        values += [(f'problem.{i}', text) for i, text in enumerate(status['problems'])]
        unsupported = dict(client.unsupported)
        values += [(f'unsupported.{name}', f'{answer}; not sent again on this connection')
                   for name, answer in unsupported.items()]
        # replies of the wrong kind, counted per command (those of unsupported ones too)
        values += [(f'wrong_reply.{name}', f'{answer} ({count}x)')
                   for name, (count, answer) in dict(client.wrong_replies).items()]
        # identity getters that failed otherwise (no reply, another NACK)
        values += [(f'identity.{name}', how) for name, how in device.identity.problems.items()
                   if name not in unsupported]
        values += [('link', client.description)] + [
            (f'link.{k}', str(v)) for k, v in client.stats.items()
        ] + [('link.garbage_bytes', str(client.garbage_bytes)),
             ('link.reads', 'batched (one write per poll)' if client.batching else
              'one request at a time' + (' (batched reads came back incomplete)'
                                         if client.batch_reads else ''))]
        part = StatusPart.from_flags('device', active, values)
        if status.get('emergency_stop'):
            part.level = max(part.level, Level.WARN)
            part.message = 'emergency stop flag set (MOT_SetEmgStopAxes 0 clears it); ' + (
                part.message)
            part.values.append(('emergency_stop', 'True'))
        texts = [t for t in status.get('errors', {}).values() if t]
        if texts:
            part.message += ' | ' + '; '.join(texts)
        if unsupported:  # informational: an optional function the device lacks
            part.message += ' | device does not know: ' + ', '.join(unsupported)
        wrong = [name for name in client.wrong_replies if name not in unsupported]
        if wrong:  # answered, but not as the protocol says: named, not called silence
            part.message += ' | wrong kind of reply from: ' + ', '.join(wrong)
        parts.append(part)
        return parts

    def mode(self) -> str:
        status = self.device.status_snapshot()
        if status.get('emergency_stop'):
            return 'emergency_stop'
        names = [a.flag.name for a in SYSTEM_STATE.decode(status.get('system', {}).get('SYS', 0))]
        return '+'.join(names) if names else 'manual'

    def axis_details(self, joint: str) -> dict[str, object]:
        status = self.device.status_snapshot()
        registers = status.get('axes', {}).get(joint)
        system = status.get('system', {})
        if registers is None:
            return {}
        active = axis_flags(registers)
        names = {a.flag.name for a in active}
        details: dict[str, object] = {
            'active_errors': sorted({a.key for a in active if a.flag.level > Level.OK}),
            'homed': not registers.get('OPR', 0) & (1 << 1),
            'calibrated': not registers.get('OPR', 0) & (1 << 1),
        }
        if 'fault' in names:
            details['state'] = AxisStateCode.FAULT
        elif 'homing_active' in names:
            details['state'] = AxisStateCode.HOMING
        elif 'axis_off' in names:
            details['state'] = AxisStateCode.DISABLED
        elif system.get('SYS', 0) & (1 << 2) and self.device.axis(joint) in (1, 2):
            details['state'] = AxisStateCode.SCANNING
        return details

    def errors(self) -> list[str]:
        status = self.device.status_snapshot()
        system = status.get('system', {})
        flags = [a.key for a in CSR.decode(system.get('CSR', 0)) if a.flag.level > Level.OK]
        return flags + [text for text in status.get('errors', {}).values() if text]


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
        if not self.device.has_gps:
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
        heading = self.device.gps_heading()
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
        device.leave_device_programs()
        device.client.goto_lla(slot, GeoPoint(target.longitude, target.latitude,
                                               target.altitude))
        return f'GPS_SetTargetLLA + GPS_GoToTarget on target {slot}'
