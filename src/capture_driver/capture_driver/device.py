"""The Capture pedestal as a :class:`~gimbal_driver_common.device.Device` (no ROS).

:class:`CaptureDevice` wraps one :class:`~.client.CaptureClient` and speaks SI units and
REP-103 signs: every degree <-> radian conversion, the per-joint direction (Capture yaw
counts clockwise) and the gear ratio of the scan limits happen here and nowhere else. The
controller (``gimbal_driver_common.controller``) runs it: it opens and reopens the link,
polls :meth:`CaptureDevice.read`, sends moves, jogs and stops, and asks
:meth:`CaptureDevice.refusal` before motion. Homing, the device's preset slots (all of
them), its own scans and the register-based status are small capability objects; the
device's extras (IMU, GPS, rangefinder, video tracker, digital I/O, loops, levelling,
gyro drift, ``~/command``) are the part :attr:`CaptureDevice.functions`
(:class:`~.functions.CaptureFunctions`), whose methods the node's services call through
``controller.call``; the device's own programs (scan, loops) are the part
:attr:`CaptureDevice.programs` (:class:`~.programs.DevicePrograms`)."""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from gimbal_driver_common.config import ControllerConfig
from gimbal_driver_common.device import (
    Device,
    DeviceInfo,
    JointSample,
    Moves,
    PostedWrite,
)
from gimbal_driver_common.diagnostics import Level
from gimbal_driver_common.errors import DeviceRefused
from gimbal_driver_common.joint_command import check_positions
from gimbal_driver_common.periodic import Period
from gimbal_driver_common.transport import ByteStream, SerialStream, TcpStream

from .capabilities import (
    CaptureGeolocation,
    CaptureHoming,
    CapturePresets,
    CaptureScans,
    CaptureTargetPointing,
)
from .client import CaptureClient
from .device_requests import IDENTITY_GETTERS, Identity
from .errors import REQUEST_ERRORS
from .functions import CaptureFunctions
from .motion import PostedMoves
from .programs import DevicePrograms
from .status import CaptureStatus, axis_flags

LOG = logging.getLogger('capture_driver.device')

#: what ``hardware_id``, diagnostics and ~/status say for an identity the device did not give
UNKNOWN = 'unknown'


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

    def to_device(self, joint: str, radians: float) -> float:
        """rad (REP-103) -> device degrees on this joint's axis."""
        return math.degrees(radians) * self.direction[joint]

    def from_device(self, joint: str, degrees: float) -> float:
        """device degrees -> rad (REP-103)."""
        return math.radians(degrees * self.direction[joint])

    def link_description(self) -> str:
        if self.transport == 'tcp':
            return f'tcp://{self.host}:{self.port}'
        return f'serial://{self.serial_port}?baudrate={self.baudrate}'

    def open_stream(self) -> ByteStream:
        if self.transport == 'tcp':
            return TcpStream(self.host, self.port, connect_timeout=2.0)
        return SerialStream(self.serial_port, self.baudrate)



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
    """One Capture controller in SI units; thread-safe (the client serialises requests).
    Its parts: ``programs`` (the device's own scan and loops), the capability objects, and
    ``functions`` (the extras), each handed what it uses."""

    def __init__(self, settings: CaptureSettings) -> None:
        super().__init__()  # the controller attaches its config (live limits) and logger
        self.settings = settings
        self.client = CaptureClient(
            settings.open_stream, group=settings.group_id, timeout=settings.request_timeout,
            expect_greeting=settings.transport == 'tcp',
            keepalive_period=settings.keepalive_period, batch_reads=settings.batch_reads,
            link_lock=self.link_lock)
        self._status: dict[str, Any] = {}
        self._status_lock = threading.Lock()
        self._warned: dict[str, float] = {}
        #: the identity the device gave at the last open (what it did not: ``problems``)
        self.identity = Identity()
        self.programs = DevicePrograms(self.client)
        presets, status = CapturePresets(self), CaptureStatus(self)
        self.functions = CaptureFunctions(self.client, settings, self.programs, status,
                                          presets, checks=self)
        self.capabilities.homing = CaptureHoming(self)
        self.capabilities.geolocation = CaptureGeolocation(self)
        self.capabilities.target_pointing = CaptureTargetPointing(self)
        self.capabilities.presets = presets
        self.capabilities.scans = CaptureScans(self)
        self.capabilities.status = status

    # ----------------------------------------------------------- units
    def to_device(self, joint: str, radians: float) -> float:
        """rad (REP-103) -> device degrees on this joint's axis."""
        return self.settings.to_device(joint, radians)

    def from_device(self, joint: str, degrees: float) -> float:
        """device degrees -> rad (REP-103)."""
        return self.settings.from_device(joint, degrees)

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
        functions = self.functions
        functions.probe(self.log.warning)
        self.programs.clear()
        self.programs.scanning = bool(client.optional('SCN_IsScanOn'))
        client.start()
        self.log.info(
            f'Capture controller on {client.description}: IMU '
            f'{"yes" if functions.has_imu else "no"}, GPS {"yes" if functions.has_gps else "no"}')
        return device_info(ident, self.settings.link_description())

    def close(self) -> None:
        self.client.stop()
        with self._status_lock:
            self._status = {}

    def link_healthy(self) -> bool:
        return self.client.connected

    def description(self) -> str:
        return self.settings.link_description()

    # ------------------------------------------------------------ poll
    def background_reads(self) -> list[tuple[Period, Callable[[], None]]]:
        """The registers, on the controller's sensors thread (not in the joint poll: a
        register the device answers late or never does not hold up joint_states): every
        ``status_period`` (read at each run: a run-time parameter), and at once after
        :meth:`expire_status`. The thread sleeps between (it ticked at 20 Hz to look
        whether the registers were due: a wake-up costs about what a quick job does)."""
        return [(lambda: self.settings.status_period, self.refresh_status)]

    def read(self) -> JointSample | None:
        """Load position and speed of every axis (the registers are a background read).

        ``moving`` stays empty: the speed read every cycle is the freshest motion signal
        (the SRL motion-complete bit is read only every ``status_period``), so the
        controller's one rule applies.
        """
        try:
            # one write for every axis: see CaptureClient.read_many
            return self._sample(self.client.read_many(self._poll_reads()))
        except REQUEST_ERRORS as exc:  # an answer of the wrong kind too: the link stays
            self._warn('poll', f'poll skipped: {exc}', 5.0)
            return None

    def request_read(self, deliver: Callable[[JointSample], object]) -> bool:
        """:meth:`read` without waiting for the answers (``CaptureClient.ask_many``):
        the reader thread hands the sample to ``deliver`` (the device thread wakes once a
        poll instead of twice); until each getter is known to answer with data, and
        whenever the client reads one request at a time, :meth:`read` does it (False)."""
        def take(values: list[Any]) -> None:
            deliver(self._sample(values))

        try:
            return self.client.ask_many(self._poll_reads(), take)
        except REQUEST_ERRORS as exc:  # settled here: as read() does
            self._warn('poll', f'poll skipped: {exc}', 5.0)
            return True

    def _poll_reads(self) -> list[tuple[str, int | None]]:
        return [(name, self.axis(joint)) for joint in self.joint_names
                for name in ('MOT_GetLoadPosition', 'MOT_GetMotorSpeed')]

    def _sample(self, values: list[Any]) -> JointSample:
        joints = self.joint_names
        positions = {joint: self.from_device(joint, values[2 * i])
                     for i, joint in enumerate(joints)}
        velocities = {joint: self.from_device(joint, values[2 * i + 1])
                      for i, joint in enumerate(joints)}
        stamp = time.time()
        with self._status_lock:
            currents = self._status.get('current', {})
        return JointSample(
            positions=positions, velocities=velocities, stamp=stamp,
            currents={j: currents[j] for j in self.joint_names if j in currents})

    def refresh_status(self) -> None:
        """Registers, currents (A) and error strings, cached for diagnostics, ~/status and
        the axis refusals; also tells which device programs (scan, loops) run."""
        client = self.client
        status: dict[str, Any] = {'axes': {}, 'current': {}, 'problems': []}
        for joint in self.joint_names:
            axis = self.axis(joint)
            try:
                # the current in the registers' batch: one round trip an axis (a device
                # without it has no current in ~/status)
                registers = client.registers(axis, also=('MOT_GetMotorCurrent',))
                current = registers.pop('MOT_GetMotorCurrent', None)
                status['axes'][joint] = registers
                if current is not None:
                    status['current'][joint] = current / 1000.0
            except REQUEST_ERRORS as exc:
                status['problems'].append(f'{joint}: {exc}')
        try:
            system = client.registers(None, also=('MOT_GetEmgStopAxes',))
            emergency_stop = system.pop('MOT_GetEmgStopAxes', None)
            status['system'] = system
            status['errors'] = client.error_strings(system.get('CSR', 0))
            if emergency_stop is not None:
                status['emergency_stop'] = bool(emergency_stop)
        except REQUEST_ERRORS as exc:
            status['problems'].append(f'system: {exc}')
        status['refusals'] = {joint: self._axis_refusal(joint, registers)
                              for joint, registers in status['axes'].items()}
        self.programs.from_system_state(status.get('system', {}).get('SYS', 0))
        with self._status_lock:
            self._status = status

    def status_snapshot(self) -> dict[str, Any]:
        with self._status_lock:
            return self._status

    def expire_status(self) -> None:
        """Read the registers at once (after a command that changes them), on the sensors
        thread."""
        self.read_background_now()

    # ---------------------------------------------------------- motion
    def move(self, moves: Moves) -> None:
        """Absolute moves; the whole set-up of every axis under one hold of the link
        lock, so the poll does not interleave its reads."""
        with self.client.link_lock:
            self.programs.leave()
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
        by :meth:`settle` when the link lock is next taken), so the joint_command
        callback writes it without waiting; not a jog, nor while a device program runs (a
        move ends it first, with requests that wait)."""
        if jogs or not moves or self.programs.any:
            return None
        written = self.client.post_moves(self._axis_moves(moves))
        if written is None:
            return None
        return PostedWrite(dict(moves), {}, replies=len(written.waitings), expected=written)

    def settle(self, posted: PostedWrite) -> bool:
        assert isinstance(posted.expected, PostedMoves)
        return self.client.settle_posted(posted.expected)

    def jog(self, velocities: dict[str, float]) -> None:
        with self.client.link_lock:
            self.programs.leave()
            for joint, velocity in velocities.items():
                if velocity == 0.0:
                    self.client.stop_axis(self.axis(joint))
                else:
                    self.client.jog(self.axis(joint), self.to_device(joint, velocity),
                                    math.degrees(self.settings.acceleration))

    def stop(self, joints: Sequence[str] | None = None) -> None:
        """Send the whole stop now; raise if it failed. None: every axis, then the preset
        loop, the target loop and the scan (the client's ``stop_axes``: one write, the
        answers read afterwards); else those axes. A refusal of SCN_StopScan fails the
        stop only while the driver knows a scan runs: a controller without the scan
        functions refuses it."""
        if joints is None:
            axes = [self.axis(j) for j in self.joint_names]
        else:
            axes = [self.axis(j) for j in joints]
        with self.client.link_lock:
            answers = self.client.stop_axes(axes, programs=joints is None)
            problems = [str(exc) for exc in answers.errors]
            if joints is None:
                scan = answers.programs.get('SCN_StopScan')
                if scan is not None and self.programs.scanning:
                    problems.append(str(scan))
                self.programs.clear()
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

    def check_pose(self, pose: dict[str, float], what: str) -> None:
        """The core's one pose check (unknown joint, outside the live limits) of a pose
        the device itself moves to, naming ``what`` (a preset, a target, ...)."""
        check_positions(pose, self.attached_config().limits, what)

    def attached_config(self) -> ControllerConfig:
        """The controller's configuration: the controller attaches it before any request
        reaches the device, so a request without one is refused, not crashed."""
        if self.config is None:
            raise DeviceRefused('the device is not attached to a controller')
        return self.config

