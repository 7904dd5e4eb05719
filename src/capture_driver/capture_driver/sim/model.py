"""Capture pedestal simulator: the device model.

:class:`PedestalModel` is one physical pedestal shared by every connection, as the real
controller is: motion physics per axis, homing, scans, presets with looping, GPS targets,
IMU, the keep-alive supervision, registers whose bits follow the motion, fault injection,
and the execution of one request (its handlers are in ``handlers`` and ``table``).

Assumptions where the spec is silent are marked "sim:" in comments."""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Iterable
from typing import TYPE_CHECKING

from gimbal_driver_common.sim_requests import RequestFaults

from ..protocol import BY_OPCODE, COMMANDS, Frame, GeoPoint, PresetRecord, ProtocolError, ReplyCode
from ..protocol import registers as reg
from ..protocol.datatypes import DataType, encode_value
from ..protocol.geometry import aim_at
from .axis import (
    FAULTS,
    GYRO_BIAS,
    SYSTEM_FAULTS,
    TILT_HARD_LIMIT,
    AxisModel,
    RequestRejected,
    ScanState,
    command_names,
)
from .handlers import CommandHandlers
from .table import HANDLERS

if TYPE_CHECKING:
    from .transport import CaptureSession

LOG = logging.getLogger('capture_sim')

#: s the physics thread may wake later than its period before the simulator counts itself
#: as not having run (a loaded machine): the host's packets then wait unread in the socket,
#: so that time is not the host's silence and does not run the keep-alive out
STALL_S = 0.25


class PedestalModel(CommandHandlers):
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
        #: when a connection's reader last ran (CaptureSession.poll); None: no server polls
        self.last_listened: float | None = None
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
        #: commands never answered (``mute``: received, not executed) or answered late
        #: (``delay``: the session holds the reply); by table command name
        self.request_faults = RequestFaults()
        #: play a controller that takes one packet per receive and drops the rest (the
        #: worst case for the client's batched reads; see CaptureClient.read_many)
        self.one_request_per_read = False
        #: the requests received, the last 4,000-5,000 of them (tests inspect it); a node
        #: polling at 50 Hz sends 5,000 in about 20 s, so a long-lived simulator counts
        #: from :attr:`request_counts` and :attr:`request_total`, which keep every one
        #: (a count taken from this list once stayed the same across a new request: the
        #: trim had taken the old one out)
        self.requests: list[Frame] = []
        self.request_counts: Counter[int] = Counter()  # by opcode, every request
        self.request_total = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_advance = time.monotonic()
        self.connected_sessions = 0

    # -------------------------------------------------------------- physics
    def start(self, rate_hz: float = 100.0) -> None:
        self._stop.clear()
        with self.lock:
            self._last_advance = time.monotonic()
        self._thread = threading.Thread(target=self._run, args=(rate_hz,), daemon=True,
                                        name='capture-sim-physics')
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def _run(self, rate_hz: float) -> None:
        period = 1.0 / rate_hz
        woke = time.monotonic()
        while not self._stop.wait(period):
            now = time.monotonic()
            stalled, woke = now - woke - period, now
            if stalled > STALL_S:
                with self.lock:
                    self.last_command += stalled
            self.advance()

    def advance(self) -> None:
        """Bring the model up to the current wall time.

        Called by the physics thread (so time-driven behaviour such as the keep-alive
        expiry and scans goes on between requests) and before every request: a controller
        acts on a command when it arrives and reads a position as it is then, not as it was
        at the last tick of a fixed-rate loop (which made positions up to one tick old and
        started moves up to one tick late).
        """
        with self.lock:
            now = time.monotonic()
            elapsed, self._last_advance = now - self._last_advance, now
            if elapsed > 0.0:
                self.step(elapsed * self.time_scale)

    def step(self, dt: float) -> None:
        with self.lock:
            self._check_keepalive()
            self._advance_scan()
            self._advance_looping()
            self._advance_target_looping()
            self._advance_drift_measurement(dt)
            for axis in self.axes.values():
                axis.step(dt)

    def listened(self) -> None:
        """A connection's reader ran (it had read what had arrived)."""
        self.last_listened = time.monotonic()

    def _check_keepalive(self) -> None:
        """The keep-alive expires once the host sent nothing for the allowed time while
        this simulator listened: counted up to its reader's last run, not up to now. A
        real controller's reader always runs; this one shares a process and a core with
        other work, and a reader that stood still has not heard what the host sent. The
        physics thread's own stalls are credited in :meth:`_run`. Judged up to now, a pinned
        test run saw "keep-alive expired" (the axes off) under a node polling at 50 Hz."""
        if not self.keepalive_on:
            return
        allowed = self.keepalive_timeout_ms / 1000.0 * max(self.keepalive_count, 1)
        now = time.monotonic()  # real time, not simulated
        heard_until = now if self.last_listened is None else min(now, self.last_listened)
        if heard_until - self.last_command > allowed:
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

    def set_target_detected(self, camera: int, detected: bool) -> None:
        """What the camera sees; losing the target ends manual tracking (4.11.1)."""
        with self.lock:
            if not detected:
                self.detected_targets[camera] = []
            elif not self.detected_targets[camera]:
                self.detected_targets[camera] = [(64, 48)]  # one target, 64 x 48 px
            if not detected and self.tracker_mode[camera] == 1:
                self.tracker_mode[camera] = 0

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
            # received now: the keep-alive is checked with this packet counted (it may have
            # waited unread while the simulator did not run)
            self.last_command = time.monotonic()
            self.advance()
            self.requests.append(frame)
            self.request_counts[frame.opcode] += 1
            self.request_total += 1
            if len(self.requests) > 5000:
                del self.requests[:1000]
            command = BY_OPCODE.get(frame.opcode)
            if command is not None and self.request_faults.muted(command.name):
                return b''  # mute: received and dropped, never executed or answered
            if command is not None and command.ret is DataType.NONE and \
                    self.request_faults.ignored(command.name):
                return bytes([ReplyCode.ACK])  # ignore: ACKed as always, not executed
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
