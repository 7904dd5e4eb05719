"""Capture pedestal simulator: the wire protocol over TCP (127.0.0.1) and a pseudo-terminal.

The model (:class:`PedestalModel`) is one physical pedestal shared by every connection, as
the real controller is: motion physics per axis (absolute/relative position mode and
speed mode, MOT_Update semantics, speed and acceleration ramps, software and hardware
limit switches, axis on/off, emergency stop), homing, the three device scan patterns,
15 presets with looping, GPS targets and go-to-target, IMU angles and rates, the
keep-alive supervision, and registers (MER, DER, SRH, SRL, MSR, CMER, CSR, operation,
system state) whose bits follow the motion.

Axes run on the shared trapezoidal model (``gimbal_driver_common.sim_motion``). Fault
injection (methods of :class:`PedestalModel`, and the shared control verbs of
``gimbal_driver_common.sim_control`` on stdin and the ``--control-port`` console: drop,
silence, garbage, nack, fault, clear, state, quit, plus Capture's lose, unknown, wrong, pose,
detect, dio, count): latched axis and system faults, NACK replies, lost replies, garbage
bytes, a silent device and a dropped link, replies of the wrong kind (``wrong``). A device
that knows only part of the table (``known_commands`` / ``--only``, ``unknown_commands`` /
``--unknown``) answers the rest with NACK 0xA6, or with an ACK (``ack_unknown`` /
``--ack-unknown``) as a third-party controller does.

The device is a table of opcodes, and so is the model: :data:`HANDLERS` maps every command
it executes to its handler, one row each (a table command without a row stores and returns
its value); handlers longer than a row are methods of :class:`PedestalModel`.

Assumptions where the spec is silent are marked "sim:" in comments.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

from gimbal_driver_common.sim_control import (
    ControlError,
    SimControl,
    control_request,
    control_state,
    run_simulator,
)
from gimbal_driver_common.sim_motion import AxisMotion
from gimbal_driver_common.sim_server import PtySimServer, TcpSimServer

from .protocol import (
    BY_OPCODE,
    COMMANDS,
    Frame,
    GeoPoint,
    PresetRecord,
    ProtocolError,
    ReplyByte,
    ReplyCode,
    StreamDecoder,
    degrees_to_ddmm,
)
from .protocol import registers as reg
from .protocol.datatypes import DataType, encode_value
from .protocol.geometry import aim_at

LOG = logging.getLogger('capture_sim')

#: Bits the simulator can latch as an injected axis fault (MER bit numbers).
FAULTS = {
    'can_bus_error': 0, 'short_circuit': 1, 'control_error': 3, 'communication_error': 4,
    'over_current': 8, 'i2t_error': 9, 'motor_over_temperature': 10, 'over_voltage': 12,
    'under_voltage': 13,
}
# MER bit -> CMER bit for the faults above (4.10.6 groups them).
_MER_TO_CMER = {0: 15, 1: 11, 3: 10, 8: 7, 9: 6, 12: 5, 13: 4}
SYSTEM_FAULTS = {flag.name: flag.bit for flag in reg.CSR.flags}

HOMING_SPEED = 30.0  # deg/s, sim: the stored homing profile
GENERAL_SPEED = 30.0  # deg/s, default CFG_SetGeneralSpd
TILT_HARD_LIMIT = 95.0  # deg, sim: mechanical limit switches of the tilt axis
GYRO_BIAS = 0.05  # deg/s, sim: the yaw gyro drift IMU_GyroDriftCompensation measures
DRIFT_MEASURE_TIME = 2.0  # s (simulated), sim: how long the drift calculation takes

#: the motion set-up of 7.1 (TUM aside) and the speed mode of jogs and stops
MOTION_SETUP = ('MOT_SetPositionMode', 'MOT_SetSpeedMode', 'MOT_SetPositionAbsolute',
                'MOT_SetPositionRelative', 'MOT_SetAcceleration', 'MOT_SetSpeed',
                'MOT_SendPosition', 'MOT_Update')
#: named command subsets for ``known_commands`` (``--only``): controllers that know only
#: part of the table (issue 26)
KNOWN_SETS: dict[str, tuple[str, ...]] = {
    # a third-party Cap-Track simulator: motion, load position and speed, voltage, current,
    # the motor error register and COM_Connect (it ACKs the rest: ``--ack-unknown``)
    'third-party': ('COM_Connect', *MOTION_SETUP, 'MOT_SetTum', 'MOT_GetLoadPosition',
                    'MOT_GetMotorSpeed', 'MOT_GetMotorVoltage', 'MOT_GetMotorCurrent',
                    'MOT_MerRegister'),
    # a partial controller: COM_Connect, the joint poll and the motion set-up without TUM
    'partial': ('COM_Connect', 'MOT_GetLoadPosition', 'MOT_GetMotorSpeed', *MOTION_SETUP),
}


def command_names(names: Iterable[str]) -> list[str]:
    """Table command names, with the names of :data:`KNOWN_SETS` expanded; a name that is
    neither raises KeyError naming it."""
    expanded = []
    for name in names:
        if name in KNOWN_SETS:
            expanded += KNOWN_SETS[name]
        elif name in COMMANDS:
            expanded.append(name)
        else:
            raise KeyError(f'{name!r} is neither a table command nor one of {sorted(KNOWN_SETS)}')
    return expanded


@dataclass
class AxisModel(AxisMotion):
    """One motor axis in load degrees, on the shared trapezoidal model (``AxisMotion``:
    ``target`` is the position move, ``jog_velocity`` the speed-mode velocity, ``speed``
    the profile speed, ``acceleration`` the profile acceleration and deceleration)."""

    number: int = 0
    acceleration: float = 180.0
    speed: float | None = 0.0  # sim: COM_Connect sets speed 0 (4.6.2)
    jog_velocity: float | None = 0.0
    speed_mode: bool = False
    relative: bool = True
    pending_position: float | None = None
    axis_on: bool = True
    homing: bool = False
    homed: bool = True
    mer_latched: int = 0
    der_latched: int = 0
    swls_neg: float = -180.0
    swls_pos: float = 180.0
    swls_active: bool = False
    hard_limits: tuple[float, float] | None = None
    general_speed: float = GENERAL_SPEED
    current_ma: float = 0.0
    limit_flags: int = 0  # DER bits 6/7 (software) and MER bits 6/7 (hardware) while at limit
    stored: dict[str, object] = field(default_factory=dict)

    @property
    def faulted(self) -> bool:
        return bool(self.mer_latched or self.der_latched & 0b0010_0100_0000_0011)

    @property
    def moving(self) -> bool:
        return abs(self.velocity) > 1e-6 or self.target is not None or self.homing

    def stop(self, immediate: bool = False) -> None:
        """End the move, jog or homing run (braking at the profile's rate unless immediate)."""
        super().stop(immediate)
        self.jog_velocity = 0.0
        self.homing = False

    def halt(self) -> None:
        """Immediate stop (emergency stop, fault, keep-alive expiry)."""
        self.stop(immediate=True)

    def goal(self) -> tuple[float | None, float | None]:
        if self.homing:
            return 0.0, HOMING_SPEED
        return self.target, self.speed

    def on_arrival(self) -> None:
        if self.homing:
            self.homing, self.homed = False, True
        self.target = None

    def _active_limits(self) -> tuple[float | None, float | None]:
        """The switches that stop the axis: software limits when active, hardware always."""
        lows, highs = [], []
        if self.swls_active:
            lows.append(self.swls_neg)
            highs.append(self.swls_pos)
        if self.hard_limits is not None:
            lows.append(self.hard_limits[0])
            highs.append(self.hard_limits[1])
        return (max(lows) if lows else None), (min(highs) if highs else None)

    def step(self, dt: float) -> bool:
        if self.faulted or not self.axis_on:
            self.velocity = 0.0
            return False
        previous = self.velocity
        self.set_limits(*self._active_limits())
        came_to_rest = super().step(dt)
        change = self.velocity - previous
        self.current_ma = 200.0 + 5.0 * abs(self.velocity) + 0.5 * abs(change) / max(dt, 1e-6)
        self._enforce_limits()
        return came_to_rest

    def _enforce_limits(self) -> None:
        """Limit-switch flags while the axis rests on a switch (the motion model has already
        stopped it there); a move or jog still pushing outward is dropped."""
        self.limit_flags = 0
        checks = []
        if self.swls_active:
            checks.append((self.swls_neg, self.swls_pos, 'software'))
        if self.hard_limits is not None:
            checks.append((*self.hard_limits, 'hardware'))
        for low, high, kind in checks:
            bit = None
            if self.position <= low + 1e-6:
                bit = 7
                if self.position < low or self.velocity < 0 or (
                        self.target is not None and self.target < low):
                    self.position = low
                    self.halt()
            elif self.position >= high - 1e-6:
                bit = 6
                if self.position > high or self.velocity > 0 or (
                        self.target is not None and self.target > high):
                    self.position = high
                    self.halt()
            if bit is not None:  # the switch stays active while the axis rests on it
                self.limit_flags |= (1 << bit) << (0 if kind == 'hardware' else 16)

    # ---------------------------------------------------------------- registers
    def mer(self) -> int:
        value = self.mer_latched | (self.limit_flags & 0xC0)
        return value

    def der(self) -> int:
        value = self.der_latched | ((self.limit_flags >> 16) & 0xC0)
        return value

    def srh(self) -> int:
        value = 1  # drive initialised
        if self.target is None and not self.homing and abs(self.velocity) < 1e-6:
            value |= reg.SRH_TARGET_REACHED
        if self.limit_flags & 0x40 or (self.limit_flags >> 16) & 0x40:
            value |= 1 << 6
        if self.limit_flags & 0x80 or (self.limit_flags >> 16) & 0x80:
            value |= 1 << 7
        if self.faulted:
            value |= reg.SRH_FAULT
        return value

    def srl(self) -> int:
        value = 0
        if self.homing:
            value |= reg.SRL_HOMING_ACTIVE
        if not self.moving:
            value |= reg.SRL_MOTION_COMPLETE
        if self.axis_on:
            value |= reg.SRL_AXIS_ON
        return value

    def msr(self) -> int:
        value = 1
        if self.mer_latched & (1 << 3):
            value |= 1 << 3
        if self.limit_flags & 0x40 or (self.limit_flags >> 16) & 0x40:
            value |= 1 << 6
        if self.limit_flags & 0x80 or (self.limit_flags >> 16) & 0x80:
            value |= 1 << 7
        if not self.moving:
            value |= 1 << 9
        if self.axis_on:
            value |= 1 << 13
        return value

    def cmer(self) -> int:
        value = 0
        if self.faulted:
            value |= 1
        if self.axis_on:
            value |= 1 << 1
        if not self.moving:
            value |= 1 << 2
        for mer_bit, cmer_bit in _MER_TO_CMER.items():
            if self.mer_latched & (1 << mer_bit):
                value |= 1 << cmer_bit
        if self.limit_flags & 0x80:
            value |= 1 << 8
        if self.limit_flags & 0x40:
            value |= 1 << 9
        if (self.limit_flags >> 16) & 0x80:
            value |= 1 << 13
        if (self.limit_flags >> 16) & 0x40:
            value |= 1 << 14
        return value

    def operation(self) -> int:
        return 0 if self.homed else reg.OPR_HOMING_NOT_COMPLETED


class RequestRejected(Exception):
    """Answer the request with this NACK code; ``reason`` becomes the protocol error string."""

    def __init__(self, code: ReplyCode, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


@dataclass
class ScanState:
    waypoints: list[tuple[float, float]]
    index: int = 0
    direction: int = 1


class PedestalModel:
    """A 2- or 3-axis Capture pedestal with controller; thread-safe."""

    def __init__(
        self,
        axes: int = 2,
        gps: bool = True,
        imu: bool = True,
        gear_ratio: float = 1.0,
        time_scale: float = 1.0,
        serial_number: int = 24017,
        firmware: str = '2.24.0',
        unknown_commands: Iterable[str] = (),
        known_commands: Iterable[str] | None = None,
        ack_unknown: bool = False,
    ) -> None:
        if axes not in (2, 3):
            raise ValueError('the simulator models 2 or 3 axes')
        self.lock = threading.RLock()
        self.axes = {n: AxisModel(number=n) for n in range(1, axes + 1)}
        self.axes[2].hard_limits = (-TILT_HARD_LIMIT, TILT_HARD_LIMIT)
        self.gps_present = gps
        self.imu_present = imu
        self.gear_ratio = gear_ratio
        self.time_scale = time_scale
        self.serial_number = serial_number
        self.firmware = firmware
        self.part_number = f'CAP-PT{axes}-SIM'
        self.hardware_revision = 3.1
        # Opcodes this device does not know (an older firmware, or a table guess that is
        # wrong): answered 0xA6 "Opcode not Recognized" like any opcode outside the table.
        self.unknown_opcodes = {COMMANDS[name].opcode for name in unknown_commands}
        #: a device that knows only these opcodes (None: the whole table)
        self.known_opcodes = None if known_commands is None else {
            COMMANDS[name].opcode for name in command_names(known_commands)}
        #: answer ACK (0x06) instead of NACK 0xA6 to an opcode the device does not know, as
        #: a third-party controller does (getters included)
        self.ack_unknown = ack_unknown
        #: opcodes answered with the other kind of reply (fault injection: a getter gets an
        #: ACK, a setter a data packet with its opcode), after they were executed
        self.wrong_kind_opcodes: set[int] = set()
        self.emergency_stop = False
        self.stabilization = False
        self.scan: ScanState | None = None
        self.scan_params = {'yaw_min': 0.0, 'yaw_max': 0.0, 'pitch_min': 0.0, 'steps': 0,
                            'step_height': 0.0, 'speed': 0.0, 'short_path': 0}
        self.presets: dict[int, PresetRecord] = {}
        self.preset_looping: list[int] | None = None
        self.looping_delay_ms = 0.0
        self._loop_wait_until = 0.0
        self.targets: dict[int, GeoPoint] = {}
        self.gps_position = GeoPoint(34.8915, 32.1040, 65.43)  # decimal degrees, metres
        self.gps_heading = 0.0
        self.inserted_position = GeoPoint(0.0, 0.0, 0.0)
        self.inserted_heading = 0.0
        self.override_gps = False
        self.gps_fix = True  # GPS_PositionReady / HeadingReady (the `gps nofix` verb clears)
        self.keepalive_on = False
        self.keepalive_timeout_ms = 1000
        self.keepalive_count = 3
        self.last_command = time.monotonic()
        self.csr_latched = 0
        self.protocol_error = ''
        self.stored: dict[tuple[str, int], object] = {}
        # video tracker per camera index (the group byte, 4.11), GPS target looping,
        # IMU gyro drift per sensor (4.5.28-30: 0 client, 1 base, 2 load, 3 middle)
        self.tracker_present = True
        self.digital_io_present = True  # COM_set/getDigitalIO exist from firmware 2.22.0
        self.tracker_mode = dict.fromkeys(range(4), 0)  # 0 off, 1 manual, 2 auto
        # targets each camera detects (5.1.5 width x height, up to 5); none = no detection
        self.detected_targets: dict[int, list[tuple[int, int]]] = {c: [] for c in range(4)}
        self.target_looping: list[int] | None = None
        self.gyro_bias = dict.fromkeys(range(4), GYRO_BIAS)
        self.gyro_drift = dict.fromkeys(range(4), 0.0)
        self.drift_measuring: dict[int, float] = {}  # sensor -> simulated seconds left
        # fault injection
        self.nack_queue: deque[tuple[ReplyCode, int | None]] = deque()
        self.nack_all: ReplyCode | None = None  # NACK every request with this code
        self.drop_replies = 0
        #: play a controller that takes one packet per receive and drops the rest (the
        #: worst case for the client's batched reads; see CaptureClient.read_many)
        self.one_request_per_read = False
        self.requests: list[Frame] = []  # every request received (tests inspect it)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.connected_sessions = 0

    # -------------------------------------------------------------- physics
    def start(self, rate_hz: float = 100.0) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, args=(rate_hz,), daemon=True,
                                        name='capture-sim-physics')
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def _run(self, rate_hz: float) -> None:
        period = 1.0 / rate_hz
        last = time.monotonic()
        while not self._stop.wait(period):
            now = time.monotonic()
            self.step((now - last) * self.time_scale)
            last = now

    def step(self, dt: float) -> None:
        with self.lock:
            self._check_keepalive()
            self._advance_scan()
            self._advance_looping()
            self._advance_target_looping()
            self._advance_drift_measurement(dt)
            for axis in self.axes.values():
                axis.step(dt)

    def _check_keepalive(self) -> None:
        if not self.keepalive_on:
            return
        allowed = self.keepalive_timeout_ms / 1000.0 * max(self.keepalive_count, 1)
        if time.monotonic() - self.last_command > allowed:  # real time, not simulated
            # 4.6.5: the controller stops any motion and turns off the axes.
            LOG.warning('keep-alive expired: stopping and turning the axes off')
            self.keepalive_on = False
            self.scan = None
            self.preset_looping = None
            self.target_looping = None
            for axis in self.axes.values():
                axis.halt()
                axis.axis_on = False

    # ---------------------------------------------------------------- scans
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

    def _advance_scan(self) -> None:
        scan = self.scan
        if scan is None:
            return
        yaw, pitch = self.axes[1], self.axes[2]
        if yaw.target is not None or pitch.target is not None:
            return
        target_yaw, target_pitch = scan.waypoints[scan.index]
        if abs(yaw.position - target_yaw) > 1e-3 or abs(pitch.position - target_pitch) > 1e-3:
            speed = max(abs(self.scan_params['speed']), 1e-3)
            dy, dp = abs(target_yaw - yaw.position), abs(target_pitch - pitch.position)
            yaw.speed = speed
            # 4.3: pitch speed follows from the pattern so both axes arrive together
            pitch.speed = speed * dp / dy if dy > 1e-6 else speed
            yaw.target, pitch.target = target_yaw, target_pitch
            return
        if len(scan.waypoints) == 1:
            return
        nxt = scan.index + scan.direction
        if not 0 <= nxt < len(scan.waypoints):  # reverse the pattern at either end
            scan.direction = -scan.direction
            nxt = scan.index + scan.direction
        scan.index = nxt

    def _loop_point_due(self) -> bool:
        """Preset/target looping: the next point is due once the axes arrived and the
        looping delay (4.9.9) has passed since."""
        if any(a.target is not None for a in self.axes.values()):
            self._loop_wait_until = time.monotonic() + self.looping_delay_ms / 1000.0 / max(
                self.time_scale, 1e-6
            )
            return False
        return time.monotonic() >= self._loop_wait_until

    def _advance_looping(self) -> None:
        if not self.preset_looping or not self._loop_point_due():
            return
        index = self.preset_looping.pop(0)
        self.preset_looping.append(index)
        self._goto_preset(index)

    def _advance_target_looping(self) -> None:
        """4.4.14: visit the stored targets in turn, dwelling the looping delay (4.9.9)."""
        if not self.target_looping or not self._loop_point_due():
            return
        number = self.target_looping.pop(0)
        self.target_looping.append(number)
        target = self.targets.get(number)
        if target is not None:
            azimuth, elevation = aim_at(*self._system_position(), target)
            self._move_to(self.axes[1], azimuth, self.axes[1].general_speed)
            self._move_to(self.axes[2], elevation, self.axes[2].general_speed)

    def _advance_drift_measurement(self, dt: float) -> None:
        for sensor in list(self.drift_measuring):
            self.drift_measuring[sensor] -= dt
            if self.drift_measuring[sensor] <= 0.0:
                del self.drift_measuring[sensor]
                self.gyro_drift[sensor] = self.gyro_bias[sensor]

    def _tracking_active(self, camera: int) -> bool:
        """4.11.1: manual and automatic tracking run only while a target is detected."""
        return self.tracker_mode[camera] in (1, 2) and bool(self.detected_targets[camera])

    def set_target_detected(self, camera: int, detected: bool) -> None:
        """What the camera sees; losing the target ends manual tracking (4.11.1)."""
        with self.lock:
            if not detected:
                self.detected_targets[camera] = []
            elif not self.detected_targets[camera]:
                self.detected_targets[camera] = [(64, 48)]  # one target, 64 x 48 px
            if not detected and self.tracker_mode[camera] == 1:
                self.tracker_mode[camera] = 0

    def _goto_preset(self, index: int) -> None:
        record = self.presets.get(index, PresetRecord(''))
        for number, axis in self.axes.items():
            self._move_to(axis, record.angles[number - 1], axis.general_speed)

    def _move_to(self, axis: AxisModel, target: float, speed: float) -> None:
        axis.speed_mode = False
        axis.jog_velocity = 0.0
        axis.speed = speed
        axis.target = target

    # ------------------------------------------------------ fault injection
    def inject_fault(self, axis: int, fault: str) -> None:
        """Latch an axis fault (a name of :data:`FAULTS`); the axis stops at once."""
        with self.lock:
            model = self.axes[axis]
            model.mer_latched |= 1 << FAULTS[fault]
            model.halt()
            self.scan = None

    def inject_system_fault(self, name: str) -> None:
        """Set a CSR bit (a flag name of registers.CSR) until ERR_ClearErrors."""
        with self.lock:
            self.csr_latched |= 1 << SYSTEM_FAULTS[name]

    def nack_next(self, code: int = ReplyCode.EXECUTION_ERROR, opcode: int | None = None,
                  count: int = 1) -> None:
        """Answer the next ``count`` requests (with ``opcode`` if given) with a NACK byte."""
        with self.lock:
            for _ in range(count):
                self.nack_queue.append((ReplyCode(code), opcode))

    def lose_replies(self, count: int = 1) -> None:
        """Execute the next ``count`` requests but send no reply (lost frames)."""
        with self.lock:
            self.drop_replies += count

    def clear_injected(self) -> None:
        """Remove every injected fault: latched axis and system faults, queued or
        permanent NACKs, replies still to lose."""
        with self.lock:
            for axis in self.axes.values():
                axis.mer_latched = axis.der_latched = 0
            self.csr_latched = 0
            self.nack_queue.clear()
            self.nack_all = None
            self.drop_replies = 0
            self.wrong_kind_opcodes.clear()

    def set_pose(self, axis: int, degrees: float) -> None:
        with self.lock:
            self.axes[axis].position = degrees
            self.axes[axis].halt()

    # ------------------------------------------------------ request handling
    def handle(self, frame: Frame, session: CaptureSession) -> bytes:
        """Execute one request; return the reply bytes (data packet, ACK or NACK)."""
        with self.lock:
            self.last_command = time.monotonic()
            self.requests.append(frame)
            if len(self.requests) > 5000:
                del self.requests[:1000]
            if self.nack_all is not None:
                self.protocol_error = f'injected NACK 0x{int(self.nack_all):02X}'
                return bytes([self.nack_all])
            for i, (code, opcode) in enumerate(self.nack_queue):
                if opcode is None or opcode == frame.opcode:
                    del self.nack_queue[i]
                    self.protocol_error = f'injected NACK 0x{int(code):02X}'
                    return bytes([code])
            try:
                reply = self._execute(frame, session)
            except RequestRejected as exc:
                self.protocol_error = exc.reason
                if exc.code == ReplyCode.INVALID_COMMAND:
                    self.csr_latched |= reg.CSR_PROTOCOL_ERROR
                reply = bytes([exc.code])
            if self.drop_replies:
                self.drop_replies -= 1
                return b''
            return reply

    def _axis(self, frame: Frame) -> AxisModel:
        axis = self.axes.get(frame.axis)
        if axis is None:
            raise RequestRejected(ReplyCode.INVALID_COMMAND,
                                  'Axis not exist in the system' if frame.axis else
                                  'Invalid Axis 0 in motor command')
        return axis

    def _motion_allowed(self, axis: AxisModel | None = None) -> None:
        if self.emergency_stop:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Emergency stop flag is set')
        if axis is not None and axis.faulted:
            raise RequestRejected(ReplyCode.EXECUTION_ERROR, 'Axis in fault: reset faults')
        if axis is not None and axis.homing:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Command not valid while homing')

    def knows(self, opcode: int) -> bool:
        """The device knows this opcode (table, ``unknown_commands``, ``known_commands``)."""
        return opcode in BY_OPCODE and opcode not in self.unknown_opcodes and (
            self.known_opcodes is None or opcode in self.known_opcodes)

    def _execute(self, frame: Frame, session: CaptureSession) -> bytes:
        cmd = BY_OPCODE.get(frame.opcode)
        if cmd is None or not self.knows(frame.opcode):
            if self.ack_unknown:  # sim: executes nothing, raises no protocol-error flag
                return bytes([ReplyCode.ACK])
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Opcode not Recognized')
        if not session.connected and cmd.name != 'COM_Connect':
            # sim: commands are processed only after COM_Connect (4.6.2)
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'COM_Connect first')
        try:
            arg = cmd.decode_request(frame)
        except ProtocolError as exc:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid input') from exc
        if cmd.axis.name == 'motor':
            self._axis(frame)
        elif cmd.axis.in_group_byte:
            if not cmd.axis.low <= frame.group <= cmd.axis.high:
                raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid input')
        elif cmd.axis.name != 'none':
            try:
                cmd.axis.check(frame.axis, cmd.name)
            except ProtocolError as exc:
                raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Invalid input') from exc
        if cmd.name.startswith(('GPS_', 'ERR_GetGps')) and not self.gps_present and not (
            cmd.name.startswith(('GPS_SetInserted', 'GPS_GetInserted', 'GPS_SetOvd',
                                 'GPS_GetOvd', 'GPS_SetTarget', 'GPS_GetTarget',
                                 'GPS_GoToTarget', 'GPS_Clear'))
        ):
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'GPS commands not available')
        if cmd.name.startswith('IMU_') and not self.imu_present:
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'IMU commands not available')
        if (self.scan is not None and cmd.name.startswith('MOT_') and not cmd.replies_with_data
                and cmd.name != 'MOT_SetEmgStopAxes'):
            # 4.3: while scanning, motor commands other than reads are refused with 0xA6
            raise RequestRejected(ReplyCode.INVALID_COMMAND, 'Command not valid while scanning')
        handler = HANDLERS.get(cmd.name)
        if handler is not None:
            result = handler(self, frame, arg, session)
        else:
            result = self._generic(cmd.name, frame, arg)
        data_reply = cmd.replies_with_data != (frame.opcode in self.wrong_kind_opcodes)
        if not data_reply:
            return bytes([ReplyCode.ACK])
        data = encode_value(cmd.ret, result, cmd.name) if cmd.replies_with_data else bytes(4)
        return Frame(frame.group, frame.axis, frame.opcode, data).encode()

    def _generic(self, name: str, frame: Frame, arg: object) -> object:
        """Setters store, getters return what was stored (or a zero of the right type)."""
        group, _, rest = name.partition('_')
        key_rest = rest[3:] if rest[:3].lower() in ('set', 'get') else rest
        cmd = COMMANDS[name]
        key = (f'{group}_{key_rest.lower()}',
               frame.group if cmd.axis.in_group_byte else frame.axis)
        if cmd.replies_with_data:
            if key in self.stored:
                return self.stored[key]
            return {DataType.BOOL: False, DataType.ASCII: '', DataType.IPV4: '0.0.0.0',
                    DataType.LLA: GeoPoint(0.0, 0.0, 0.0),
                    DataType.PRESET: PresetRecord(''), DataType.TARGETS: ()}.get(cmd.ret, 0)
        if arg is not None:
            self.stored[key] = arg
        return None

    # ------------------------------------------------ handlers too long for one table row
    # (the table itself, HANDLERS, follows the class: every command the model executes)
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
        level = float(self.stored.get(('IMU_levelingvalue', frame.axis), 0.0))
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


#: one handler per command: (model, request frame, decoded argument, session) -> the value
#: a getter returns (None for the rest); a command without an entry stores and returns
#: its value (PedestalModel._generic)
Handler = Callable[[PedestalModel, Frame, Any, 'CaptureSession'], Any]


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


def _error_text(model: PedestalModel, bit: int, text: str) -> str:
    return text if model._system_register() & (1 << bit) else ''


def _error_string(bit: int, text: str) -> Handler:
    """An ERR_Get...String: ``text`` while its CSR bit is set, else empty (4.10.22)."""
    return lambda model, frame, arg, session: _error_text(model, bit, text)


def _scan_parameter(key: str, convert: Callable[[Any], Any] = lambda arg: arg) -> Handler:
    return lambda model, frame, arg, session: model.scan_params.__setitem__(key, convert(arg))


def _scan(pattern: str) -> Handler:
    return lambda model, frame, arg, session: model._start_scan(pattern)


def _motor_position(model: PedestalModel, frame: Frame, arg: object, session: object) -> float:
    return model._axis(frame).position * model.gear_ratio


M = PedestalModel
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
    'VDT_isTrackingOn': _of_camera(PedestalModel._tracking_active),
    'VDT_isAutoModeOn': _of_camera(lambda model, camera: model.tracker_mode[camera] == 2),
    'VDT_isTargetDetected': _of_camera(
        lambda model, camera: bool(model.detected_targets[camera])),
    'VDT_GetTargetsList': _of_camera(lambda model, camera: model.detected_targets[camera][:5]),
}
del M


class CaptureSession:
    """One connection: byte parsing, the TCP greeting and reply generation."""

    def __init__(self, model: PedestalModel, greet: bool) -> None:
        self.model = model
        self.decoder = StreamDecoder()
        self.connected = False
        self._greeting = COMMANDS['COM_Connect'].encode() if greet else b''

    def poll(self) -> bytes:
        greeting, self._greeting = self._greeting, b''
        return greeting

    def on_bytes(self, data: bytes) -> bytes:
        out = bytearray()
        handled = False
        for item in self.decoder.feed(data):
            if isinstance(item, Frame):
                if handled and self.model.one_request_per_read:
                    continue
                handled = True
                out += self.model.handle(item, self)
            elif isinstance(item, ReplyByte):
                continue  # the host never sends reply bytes; ignore
            elif item.reason == 'checksum mismatch':
                out.append(ReplyCode.WRONG_CHECKSUM)  # 2.1: a bad checksum gets 0xF6
        return bytes(out)

    def on_disconnect(self) -> None:
        self.connected = False


class CaptureSimulator:
    """The model plus its TCP and/or pty servers."""

    def __init__(self, model: PedestalModel | None = None, tcp_port: int | None = 0,
                 pty: bool = False, pty_link: str | None = None) -> None:
        self.model = model or PedestalModel()
        self.tcp = (TcpSimServer(lambda: CaptureSession(self.model, greet=True), port=tcp_port)
                    if tcp_port is not None else None)
        self.pty = (PtySimServer(lambda: CaptureSession(self.model, greet=False), pty_link)
                    if pty else None)
        self._controls: SimControl | None = None

    def start(self) -> CaptureSimulator:
        self.model.start()
        for server in (self.tcp, self.pty):
            if server is not None:
                server.start()
        return self

    def stop(self) -> None:
        for server in (self.tcp, self.pty):
            if server is not None:
                server.stop()
        self.model.stop()

    def __enter__(self) -> CaptureSimulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def drop_link(self, offline_for: float = 0.0) -> None:
        for server in (self.tcp, self.pty):
            if server is not None:
                server.drop_link(offline_for)

    def inject_garbage(self, data: bytes) -> None:
        for server in (self.tcp, self.pty):
            if server is not None:
                server.inject(data)

    def set_silent(self, silent: bool) -> None:
        for server in (self.tcp, self.pty):
            if server is not None:
                server.set_silent(silent)

    def control(self, line: str) -> str:
        """Run one control request (the shared verbs plus Capture's); return the answer."""
        return self.controls.execute(line)

    @property
    def controls(self) -> SimControl:
        if self._controls is None:
            self._controls = self._make_controls()
        return self._controls

    def _make_controls(self) -> SimControl:
        model = self.model
        links = [server for server in (self.tcp, self.pty) if server is not None]
        control = SimControl('capture_sim', self.state, links=links, nack=self._nack,
                             fault=self._fault, fault_names=(*FAULTS, *SYSTEM_FAULTS),
                             clear_device=model.clear_injected)
        control.add_verb('lose', lambda a: model.lose_replies(int(a[0]) if a else 1),
                         'lose [COUNT]')
        control.add_verb('unknown', lambda a: self._toggle(model.unknown_opcodes, a),
                         'unknown COMMAND [on|off]')
        control.add_verb('wrong', lambda a: self._toggle(model.wrong_kind_opcodes, a),
                         'wrong COMMAND [on|off]  (answer it with the other kind of reply)')
        control.add_verb('gps', model.set_gps_from_console,
                         'gps LAT LON ALT HEADING | gps nofix: the GPS position (deg, deg, m) '
                         'and heading (deg clockwise from north), or no fix')
        control.add_verb('inserted', model.set_inserted_from_console,
                         'inserted LAT LON ALT HEADING | inserted off: the user-inserted '
                         'position and heading with the override flag set, or the flag off')
        control.add_verb('pose', lambda a: model.set_pose(int(a[0]), float(a[1])),
                         'pose AXIS DEG')
        control.add_verb('detect', lambda a: model.set_target_detected(
            int(a[0]), a[1].lower() in ('1', 'on', 'true')), 'detect CAMERA on|off')
        control.add_verb('dio', self._dio, 'dio N 0|1')
        control.add_verb('count', self._count, 'count COMMAND')
        return control

    def _nack(self, args: list[str]) -> str | None:
        """``nack on [HEXCODE]`` / ``nack off`` / ``nack COMMAND|* [COUNT] [HEXCODE]``."""
        model, word = self.model, args[0]
        if word.lower() in ('on', 'off'):
            code = ReplyCode(int(args[1], 16)) if len(args) > 1 else ReplyCode.EXECUTION_ERROR
            with model.lock:
                model.nack_all = code if word.lower() == 'on' else None
                if word.lower() == 'off':
                    model.nack_queue.clear()
            return None
        opcode = None if word == '*' else COMMANDS[word].opcode
        count = int(args[1]) if len(args) > 1 else 1
        code = int(args[2], 16) if len(args) > 2 else ReplyCode.EXECUTION_ERROR
        model.nack_next(code, opcode, count)
        return None

    def _fault(self, args: list[str]) -> str | None:
        """``fault NAME [AXIS]``: an axis fault of FAULTS (MER bits latched, default axis 1),
        a CSR flag name, or ``fault BITS [AXIS]`` with a MER bit mask."""
        model, name = self.model, args[0]
        if name in SYSTEM_FAULTS:
            model.inject_system_fault(name)
            return None
        axis = int(args[1]) if len(args) > 1 else 1
        if axis not in model.axes:
            raise ControlError(f'no axis {axis}; axes {sorted(model.axes)}')
        if name in FAULTS:
            model.inject_fault(axis, name)
            return None
        bits = int(name, 0)
        with model.lock:
            model.axes[axis].mer_latched |= bits
            model.axes[axis].halt()
            model.scan = None
        return None

    def _toggle(self, opcodes: set[int], args: list[str]) -> None:
        """``COMMAND [on|off]``: add or remove the command's opcode in one of the model's
        opcode sets (unknown, wrong kind of reply)."""
        opcode = COMMANDS[args[0]].opcode
        with self.model.lock:
            if len(args) > 1 and args[1].lower() in ('off', '0', 'false'):
                opcodes.discard(opcode)
            else:
                opcodes.add(opcode)

    def _dio(self, args: list[str]) -> None:
        with self.model.lock:
            self.model.stored[('COM_digitalio', int(args[0]))] = int(
                args[1].lower() in ('1', 'on', 'true'))

    def _count(self, args: list[str]) -> str:
        opcode = COMMANDS[args[0]].opcode
        with self.model.lock:
            return str(sum(1 for f in self.model.requests if f.opcode == opcode))

    def state(self) -> dict:
        """The ``state`` answer: axes (load degrees) and the controller's modes."""
        model = self.model
        with model.lock:
            return {
                'axes': {n: {**a.snapshot(), 'axis_on': a.axis_on, 'homing': a.homing,
                             'faulted': a.faulted} for n, a in model.axes.items()},
                'scanning': model.scan is not None,
                'preset_looping': bool(model.preset_looping),
                'emergency_stop': model.emergency_stop,
                'presets': sorted(model.presets),
                'target_looping': bool(model.target_looping),
                'tracker_mode': model.tracker_mode,
                'gyro_drift': model.gyro_drift,
                'digital_io': {n: model.stored.get(('COM_digitalio', n), 0)
                               for n in range(1, 7)},
                'lrf_measuring': bool(model.stored.get(('LRF_measuring', 0))),
                'keepalive': model.keepalive_on,
                'requests': len(model.requests),
                'requests_by_command': dict(Counter(
                    BY_OPCODE[f.opcode].name if f.opcode in BY_OPCODE
                    else f'0x{f.opcode:04X}' for f in model.requests)),
                'connections': self.tcp.connections if self.tcp else 0,
                'nack_all': model.nack_all is not None,
                'ack_unknown': model.ack_unknown,
                'known_commands': None if model.known_opcodes is None else sorted(
                    BY_OPCODE[opcode].name for opcode in model.known_opcodes),
            }


#: one request to a running capture_sim's TCP console (the shared protocol)
control = control_request
#: its ``state`` answer as a dict
console_state = control_state


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog='capture_sim',
        description='Capture pedestal simulator on 127.0.0.1 (TCP) and/or a pseudo-terminal.',
    )
    parser.add_argument('--port', type=int, default=4949,
                        help='TCP port on 127.0.0.1 (0 = any free port, -1 = no TCP)')
    parser.add_argument('--pty', action='store_true', help='also serve a pseudo-terminal')
    parser.add_argument('--pty-link', default=None, help='stable symlink path for the pty')
    parser.add_argument('--axes', type=int, default=2, choices=(2, 3))
    parser.add_argument('--no-gps', action='store_true', help='simulate a system without GPS')
    parser.add_argument('--no-imu', action='store_true', help='simulate a manual system')
    parser.add_argument('--no-digital-io', action='store_true',
                        help='firmware before 2.22.0: no COM_set/getDigitalIO')
    parser.add_argument('--gear-ratio', type=float, default=1.0)
    parser.add_argument('--time-scale', type=float, default=1.0,
                        help='simulated seconds per real second (faster tests)')
    parser.add_argument('--control-port', type=int, default=0,
                        help='control console on 127.0.0.1 (0 = any free port, -1 = none); '
                             'the same verbs are read on stdin')
    parser.add_argument('--unknown', action='append', default=[], metavar='COMMAND',
                        help='play a device that does not know this table command: it '
                             'answers 0xA6 "Opcode not Recognized" (repeatable)')
    parser.add_argument('--only', action='append', default=None, metavar='NAMES',
                        help='play a device that knows only these table commands (comma-'
                             'separated, repeatable; the sets ' + ', '.join(KNOWN_SETS)
                             + ' name the command subsets of issue 26); the rest get 0xA6, '
                             'or an ACK with --ack-unknown')
    parser.add_argument('--ack-unknown', action='store_true',
                        help='answer ACK (0x06) instead of NACK 0xA6 to every opcode the '
                             'device does not know, getters included (a third-party '
                             'controller)')
    parser.add_argument('--one-request-per-read', action='store_true',
                        help='play a controller that drops every packet after the first in '
                             'one receive (the driver then reads one request at a time)')
    parser.add_argument('--log-level', default='INFO')
    args = parser.parse_args(argv)
    for name in args.unknown:
        if name not in COMMANDS:
            parser.error(f'--unknown {name}: not a command of the table')
    known = None
    if args.only is not None:
        try:
            known = command_names(n.strip() for arg in args.only for n in arg.split(',')
                                  if n.strip())
        except KeyError as exc:
            parser.error(f'--only: {exc.args[0]}')
    logging.basicConfig(level=args.log_level.upper(), format='%(name)s: %(message)s')
    model = PedestalModel(axes=args.axes, gps=not args.no_gps, imu=not args.no_imu,
                          gear_ratio=args.gear_ratio, time_scale=args.time_scale,
                          unknown_commands=args.unknown, known_commands=known,
                          ack_unknown=args.ack_unknown)
    model.digital_io_present = not args.no_digital_io
    model.one_request_per_read = args.one_request_per_read
    sim = CaptureSimulator(model, tcp_port=None if args.port < 0 else args.port,
                           pty=args.pty, pty_link=args.pty_link)
    sim.start()
    try:
        run_simulator(sim.controls, {'port': sim.tcp.port if sim.tcp else None,
                                     'pty': sim.pty.port_name if sim.pty else None},
                      args.control_port)
    finally:
        sim.stop()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
