"""Kessler kOS CineShooter simulator: the kOS network protocol on TCP 127.0.0.1.

What it models (document sections in brackets):
- motors (slider, pan, tilt by default; focus/zoom optional) with trapezoidal speed/acceleration
  physics in rotations, the documented maxima, MotorPosition when a motor becomes idle;
- calibration (MarkBegin/MarkEnd/ResetAxis, MotorCalibrated);
- password lock (UserPassword/DevicePassword; a locked device ignores most messages and
  answers a wrong password with ErrorStatus 15);
- the 30 s keep-alive: a connection silent for `keepalive_timeout` seconds is dropped;
- discovery: NetworkInfo datagrams every 5 s while no client is connected, sent to 127.0.0.1
  only (never broadcast), to `discovery_port`;
- TrajectoryData storage and validation (ErrorStatus 3), Bezier playback over time with the
  documented PlaybackStatus sequences for Live Motion (loops, reverse, rapid reverse) and
  Time Lapse (continuous and shoot-move-shoot, pre/post photos, photo counting);
- UnsupportedMessage for anything the document does not define;
- LEDStatus and SoftwareID (Get/Set), AuxInputStatus notifications (control command `aux`);
- the USB face (document "USB Notes"): `SimHidDevice` has the methods of cython-hidapi's
  `hid.device` and carries the same device model in 64-byte reports with report ID 0x01, so
  the client's USB transport runs end to end in-process; a USB session needs no password
  (UserPassword/DevicePassword get UnsupportedMessage) and takes the six-byte keep-alive;
- motion on the shared trapezoidal model (``gimbal_driver_common.sim_motion``);
- fault injection: link drop, motor offline/online, axis fault (ErrorStatus 16 + reset),
  garbage bytes, silence; from Python or with the shared control verbs
  (``gimbal_driver_common.sim_control``) on stdin and the TCP console on 127.0.0.1.

Simulated time runs `time_scale` times faster than wall time (durations, delays, exposures and
physics); keep-alive and discovery periods are wall-clock.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import socket
import sys
import threading
import time
from dataclasses import dataclass, field

from gimbal_driver_common.sim_control import (
    ControlServer,
    SimControl,
    control_request,
    run_simulator,
)
from gimbal_driver_common.sim_motion import AxisMotion
from gimbal_driver_common.sim_server import TcpSimServer

from .protocol import (
    ALL_MOTORS,
    DEFAULT_TCP_PORT,
    DISCOVERY_PERIOD_S,
    DOCUMENTED_MAXIMA,
    KEEPALIVE_DROP_S,
    MOTOR_ADDRESS_MAX,
    MOTOR_ADDRESS_MIN,
    UNCALIBRATED_TARGET,
    AuxInputStatus,
    BumpPositionSpeedAcceleration,
    DeviceGuid,
    DeviceInfo,
    DevicePassword,
    DeviceType,
    ErrorCode,
    ErrorStatus,
    FrameParser,
    GetDeviceGuid,
    GetDeviceInfo,
    GetLedStatus,
    GetMotorInfo,
    GetNetworkInfo,
    GetSoftwareId,
    GetTrajectoryData,
    LedStatus,
    MarkBeginPosition,
    MarkEndPosition,
    Message,
    MessageType,
    MotorCalibrated,
    MotorInfo,
    MotorInfoEntry,
    MotorPosition,
    MotorStatus,
    MotorStatusEntry,
    NetworkInfo,
    PlaybackMode,
    PlaybackState,
    PlaybackStatus,
    ProtocolError,
    RapidToFirstKeyFrame,
    ResetAxis,
    ResetDevice,
    SetPositionSpeedAcceleration,
    SetupPlayback,
    SoftwareId,
    StartPlayback,
    StopPlayback,
    TakePicture,
    Trajectory,
    TrajectoryData,
    UnsupportedMessage,
    UserPassword,
    decode,
    position_at,
    validate,
)
from .protocol.trajectory import AxisLimits
from .protocol.usb import REPORT_SIZE, USB_KEEPALIVE, ReportReassembler, encode_reports

LOG = logging.getLogger('kessler_kos_sim')
PHYSICS_STEP_S = 0.002          # simulated seconds per integration step
MAX_CATCH_UP_S = 5.0            # simulated seconds integrated at most per advance()
DEFAULT_RANGES = {'slider': 200.0, 'pan': 100.0, 'tilt': -40.0, 'focus': 10.0, 'zoom': 10.0}
# Locked devices still answer these (identification, keep-alive, unlocking).
ALLOWED_WHILE_LOCKED = (GetDeviceInfo, GetNetworkInfo, UserPassword)


@dataclass
class SimMotor(AxisMotion):
    """One motor in rotations on the shared trapezoidal model (``AxisMotion``); its travel
    is the calibrated range (or +-UNCALIBRATED_TARGET before calibration)."""

    address: int = 1
    role: str = 'pan'
    begin: float = 0.0
    end: float = 0.0                  # 0 = uncalibrated
    mark_begin_raw: float | None = None
    online: bool = True
    max_setup_speed: float = 0.0
    max_move_speed: float = 0.0
    max_acceleration: float = 0.0

    @property
    def is_fiz(self) -> bool:
        return self.role in ('focus', 'zoom')

    @property
    def calibrated(self) -> bool:
        return self.end != 0.0

    def travel_limits(self) -> tuple[float, float]:
        if self.calibrated:
            return min(0.0, self.end), max(0.0, self.end)
        return -UNCALIBRATED_TARGET, UNCALIBRATED_TARGET

    def clamp(self, position: float) -> float:
        low, high = self.travel_limits()  # follows calibration as it changes
        return min(max(position, low), high)

    def command(self, target: float, speed: float, acceleration: float) -> None:
        """SetPositionSpeedAcceleration: speed and acceleration capped at the maxima;
        speed 0 decelerates to a stop where the motor can."""
        speed = min(max(speed, 0.0), self.max_setup_speed)
        accel = acceleration if acceleration > 0 else self.max_acceleration
        self.acceleration = min(accel, self.max_acceleration)
        if speed == 0.0:
            self.stop()
        else:
            self.move_to(target, speed)

    def halt_now(self) -> None:
        self.stop(immediate=True)


@dataclass
class SimSettings:
    password: str = ''
    motors: tuple[str, ...] = ('slider', 'pan', 'tilt')
    precalibrated: bool = False
    time_scale: float = 1.0
    keepalive_timeout: float = KEEPALIVE_DROP_S
    device_type: int = DeviceType.CINESHOOTER
    guid: bytes = bytes.fromhex('4b4f53000000000000000000c1e55100')
    firmware: tuple[int, int, int, int] = (2, 4, 1, 7)


@dataclass
class _Playback:
    """Device-side playback state machine."""

    trajectory: Trajectory | None = None
    phase: str = 'idle'      # idle, homing, ready, delay, pre_photos, play, sms, post_photos
    setup_done: bool = False
    direction: int = 1
    loops_left: int = 0
    loop_forever: bool = False
    move_time: float = 0.0   # simulated seconds into the current pass
    pass_length: float = 0.0
    elapsed: float = 0.0     # normalised
    photos: int = 0
    phase_time: float = 0.0
    photos_in_phase: int = 0
    sms_frame: int = 0
    sms_step: str = ''
    start_after_homing: bool = False
    homing_owed: bool = False   # SetupPlayback(DelayReturn): return after StartPlayback
    homing_targets: dict[int, float] = field(default_factory=dict)
    start_at: float | None = None   # DelayMode 2: wall-clock UnixTime the move starts at
    status: int = PlaybackState.NO_MOVE


class SimulatedRig:
    """The simulated kOS device (motors, calibration, playback): state shared by every TCP
    and USB session (it survives link drops). Named apart from the driver's adapter,
    :class:`kessler_kos_driver.device.KosDevice`, which talks to it."""

    def __init__(self, settings: SimSettings) -> None:
        self.settings = settings
        self.password = settings.password
        self.lock = threading.RLock()
        self.motors: dict[int, SimMotor] = {}
        for index, role in enumerate(settings.motors):
            maxima = DOCUMENTED_MAXIMA.get(role, DOCUMENTED_MAXIMA['pan'])
            motor = SimMotor(address=index + 1, role=role, acceleration=maxima.acceleration,
                             max_setup_speed=maxima.speed,
                             max_move_speed=maxima.speed, max_acceleration=maxima.acceleration)
            if settings.precalibrated:
                motor.end = DEFAULT_RANGES.get(role, 100.0)
            self.motors[motor.address] = motor
        self.playback = _Playback()
        self.playback_mode = PlaybackMode.LIVE_MOTION
        self.led = (1, 0)
        self.software_id = 0
        self.aux_input = 0
        self.sessions: list[KosSession] = []
        self.sim_time = 0.0
        self._last_wall = time.monotonic()
        self.frames_received = 0
        self.photos_taken = 0
        self.reboot_requested = False

    # ----------------------------------------------------------------- notifications
    def broadcast(self, message: Message) -> None:
        data = message.encode()
        for session in self.sessions:
            if session.unlocked:
                session.outbox.append(data)

    def _playback_note(self, status: int) -> None:
        pb = self.playback
        pb.status = status
        addresses = sorted(pb.trajectory.axes) if pb.trajectory else sorted(self.motors)
        positions = {a: self.motors[a].position for a in addresses if a in self.motors}
        self.broadcast(PlaybackStatus(status, pb.elapsed, float(pb.photos), positions))

    def error(self, code: int, address: int = 0, session: KosSession | None = None) -> None:
        note = ErrorStatus(code, address)
        if session is not None:
            session.outbox.append(note.encode())
        else:
            self.broadcast(note)

    # ------------------------------------------------------------------------ time
    def advance(self) -> None:
        """Bring the simulation up to the current wall time (called by every session)."""
        with self.lock:
            now = time.monotonic()
            sim_dt = min((now - self._last_wall) * self.settings.time_scale, MAX_CATCH_UP_S)
            self._last_wall = now
            while sim_dt > 1e-9:
                dt = min(PHYSICS_STEP_S, sim_dt)
                sim_dt -= dt
                self._step(dt)

    def _step(self, dt: float) -> None:
        self.sim_time += dt
        pb = self.playback
        if pb.phase in ('play',):
            self._step_playback(dt)
        playing = set(pb.trajectory.axes) if pb.phase == 'play' and pb.trajectory else set()
        for motor in self.motors.values():
            if motor.address in playing:
                continue  # the playback sets these positions itself
            if motor.step(dt) and pb.phase != 'play':
                self.broadcast(MotorPosition(motor.address, motor.position))
        if pb.phase == 'homing' and not any(
                self.motors[a].moving for a in pb.homing_targets if a in self.motors):
            self._homing_done()
        elif pb.phase in ('delay', 'pre_photos', 'post_photos', 'sms'):
            self._step_timed_phase(dt)

    # --------------------------------------------------------------------- playback
    def _first_positions(self) -> dict[int, float]:
        traj = self.playback.trajectory
        assert traj is not None
        return {a: self._to_rotations(a, segs[0].p0_position) for a, segs in traj.axes.items()}

    def _to_rotations(self, address: int, normalised: float) -> float:
        motor = self.motors[address]
        return motor.begin + normalised * (motor.end - motor.begin)

    def _curve_positions(self, t: float) -> dict[int, float]:
        traj = self.playback.trajectory
        assert traj is not None
        return {
            a: self._to_rotations(a, position_at([(s.times, s.positions) for s in segs], t))
            for a, segs in traj.axes.items()
        }

    def _start_homing(self, then_start: bool) -> None:
        pb = self.playback
        traj = pb.trajectory
        assert traj is not None
        percent = traj.playback.return_to_home_percent / 100.0
        pb.homing_targets = self._first_positions()
        for address, target in pb.homing_targets.items():
            motor = self.motors[address]
            motor.acceleration = motor.max_acceleration
            motor.move_to(target, max(motor.max_move_speed * percent, 1e-3))
        pb.phase = 'homing'
        pb.start_after_homing = then_start

    def _homing_done(self) -> None:
        pb = self.playback
        pb.elapsed = 0.0
        self._playback_note(PlaybackState.MOTORS_HOME)
        if pb.start_after_homing:
            self._begin_after_setup()
        else:
            if pb.setup_done:
                self._playback_note(PlaybackState.SETUP_COMPLETED)
            pb.phase = 'ready'

    def _begin_after_setup(self) -> None:
        pb = self.playback
        traj = pb.trajectory
        assert traj is not None
        delay = traj.playback.delay_interval if traj.playback.delay_mode == 1 else 0.0
        pb.start_at = None
        if traj.playback.delay_mode == 2:
            # a date is wall-clock time: it does not run faster with --time-scale
            delay = max(0.0, traj.playback.delay_interval - time.time())
            pb.start_at = traj.playback.delay_interval
        pb.phase_time = 0.0
        if delay > 0:
            pb.phase = 'delay'
            pb.pass_length = delay
            self._playback_note(PlaybackState.DELAY_TIMER_STARTED)
        else:
            self._after_delay()

    def _after_delay(self) -> None:
        pb = self.playback
        traj = pb.trajectory
        assert traj is not None
        if traj.playback.playback_mode == PlaybackMode.LIVE_MOTION:
            self._start_pass(forward=True)
            return
        pb.phase = 'pre_photos'
        pb.phase_time = 0.0
        pb.photos_in_phase = 0
        self._playback_note(PlaybackState.PRE_MOVE_PHOTOS_STARTED)

    def _frame_time(self) -> float:
        tl = self.playback.trajectory.timelapse  # type: ignore[union-attr]
        return max(tl.delay + tl.exposure, 1e-3)

    def _start_pass(self, forward: bool, rapid: bool = False) -> None:
        pb = self.playback
        traj = pb.trajectory
        assert traj is not None
        pb.direction = 1 if forward else -1
        pb.move_time = 0.0
        if traj.playback.playback_mode == PlaybackMode.TIMELAPSE_SMS:
            pb.phase = 'sms'
            pb.sms_frame = 0
            pb.sms_step = 'frame'
            pb.phase_time = 0.0
            self._playback_note(PlaybackState.START_FORWARD)
            return
        pb.pass_length = (traj.playback.rapid_reverse_duration if rapid
                          else traj.effective_duration())
        pb.phase = 'play'
        for motor in (self.motors[a] for a in traj.axes):
            motor.halt_now()
        self._playback_note(PlaybackState.START_FORWARD if forward
                            else PlaybackState.START_REVERSE)

    def _step_playback(self, dt: float) -> None:
        pb = self.playback
        traj = pb.trajectory
        assert traj is not None
        pb.move_time += dt
        fraction = min(pb.move_time / pb.pass_length, 1.0) if pb.pass_length > 0 else 1.0
        pb.elapsed = fraction if pb.direction > 0 else 1.0 - fraction
        previous = {a: self.motors[a].position for a in traj.axes}
        for address, position in self._curve_positions(pb.elapsed).items():
            motor = self.motors[address]
            motor.position = position
            motor.velocity = (position - previous[address]) / dt
        if traj.playback.playback_mode == PlaybackMode.TIMELAPSE_CONTINUOUS:
            due = int(pb.move_time / self._frame_time())
            while pb.photos < traj.timelapse.pre_move_photos + min(
                    due, traj.timelapse.move_photos):
                self._take_photo()
        if fraction < 1.0:
            return
        for motor in (self.motors[a] for a in traj.axes):
            motor.halt_now()
        if traj.playback.playback_mode == PlaybackMode.TIMELAPSE_CONTINUOUS:
            while pb.photos < traj.timelapse.pre_move_photos + traj.timelapse.move_photos:
                self._take_photo()
        self._playback_note(PlaybackState.END_OF_MOVE)
        pl = traj.playback
        if traj.playback.playback_mode != PlaybackMode.LIVE_MOTION:
            self._start_post_photos()
            return
        if pb.direction < 0:        # back at the first key frame: play forward again
            self._start_pass(forward=True)
            return
        if pb.loop_forever or pb.loops_left > 0:
            if not pb.loop_forever:
                pb.loops_left -= 1
            self._start_pass(forward=False, rapid=bool(pl.loop_after_rapid_reverse))
            return
        self._finish()

    def _take_photo(self) -> None:
        self.playback.photos += 1
        self.photos_taken += 1

    def _start_post_photos(self) -> None:
        pb = self.playback
        pb.phase = 'post_photos'
        pb.phase_time = 0.0
        pb.photos_in_phase = 0

    def _step_timed_phase(self, dt: float) -> None:
        pb = self.playback
        traj = pb.trajectory
        assert traj is not None
        tl = traj.timelapse
        pb.phase_time += dt
        if pb.phase == 'delay':
            due = (time.time() >= pb.start_at if pb.start_at is not None
                   else pb.phase_time >= pb.pass_length)
            if due:
                self._after_delay()
        elif pb.phase in ('pre_photos', 'post_photos'):
            wanted = tl.pre_move_photos if pb.phase == 'pre_photos' else tl.post_move_photos
            while pb.photos_in_phase < wanted and pb.phase_time >= (
                    pb.photos_in_phase + 1) * self._frame_time():
                pb.photos_in_phase += 1
                self._take_photo()
            if pb.photos_in_phase >= wanted:
                if pb.phase == 'pre_photos':
                    self._start_pass(forward=True)
                else:
                    self._playback_note(PlaybackState.POST_MOVE_PHOTOS_COMPLETED)
                    self._finish()
        elif pb.phase == 'sms':
            self._step_sms()

    def _step_sms(self) -> None:
        """Shoot-move-shoot: per frame StartFrame, delay, exposure (photo), move, stopped."""
        pb = self.playback
        traj = pb.trajectory
        assert traj is not None
        tl = traj.timelapse
        if pb.sms_step == 'frame':
            self._playback_note(PlaybackState.START_FRAME)
            pb.sms_step, pb.phase_time = 'shoot', 0.0
        elif pb.sms_step == 'shoot' and pb.phase_time >= tl.delay + tl.exposure:
            self._take_photo()
            pb.sms_frame += 1
            pb.elapsed = pb.sms_frame / tl.move_photos
            for address, target in self._curve_positions(pb.elapsed).items():
                motor = self.motors[address]
                motor.acceleration = motor.max_acceleration
                motor.move_to(target, motor.max_move_speed)
            pb.sms_step = 'move'
        elif pb.sms_step == 'move' and not any(self.motors[a].moving for a in traj.axes):
            self._playback_note(PlaybackState.SMS_MOTORS_STOPPED)
            if pb.sms_frame >= tl.move_photos:
                self._playback_note(PlaybackState.END_OF_MOVE)
                self._start_post_photos()
            else:
                pb.sms_step = 'frame'

    def _finish(self) -> None:
        """FullStop: the configured move is no longer valid (document note 3)."""
        pb = self.playback
        self._playback_note(PlaybackState.FULL_STOP)
        self.playback = _Playback(status=PlaybackState.FULL_STOP, photos=pb.photos,
                                  elapsed=pb.elapsed)

    def stop_playback(self) -> None:
        pb = self.playback
        for motor in self.motors.values():
            motor.halt_now()
        self._playback_note(PlaybackState.FULL_STOP)
        self.playback = _Playback(status=PlaybackState.FULL_STOP, photos=pb.photos,
                                  elapsed=pb.elapsed)
        for motor in self.motors.values():
            if motor.online:
                self.broadcast(MotorPosition(motor.address, motor.position))

    # ------------------------------------------------------------------ handlers
    def handle(self, message: Message, frame: bytes, session: KosSession) -> None:
        """Apply one decoded client message; replies go to session.outbox."""
        self.frames_received += 1
        out = session.outbox
        if not session.unlocked and not isinstance(message, ALLOWED_WHILE_LOCKED):
            return   # "the Device will simply ignore most messages"
        if session.usb and isinstance(message, (UserPassword, DevicePassword)):
            out.append(UnsupportedMessage(frame[:64]).encode())   # "not required or supported"
            return
        if isinstance(message, GetDeviceInfo):
            out.append(self.device_info().encode())
        elif isinstance(message, GetNetworkInfo):
            # LimitedResponse would ask for a UDP limited broadcast; this simulator never
            # broadcasts, so it always answers over the TCP connection.
            out.append(self.network_info().encode())
        elif isinstance(message, DevicePassword):
            self.password = message.password
        elif isinstance(message, UserPassword):
            if message.password == self.password:
                session.unlocked = True
            else:
                session.unlocked = False
                self.error(ErrorCode.LOCKED_OUT, 0, session)
        elif isinstance(message, GetMotorInfo):
            online = [m for m in self.motors.values() if m.online]
            if not online:
                self.error(ErrorCode.NO_MOTORS, 0, session)
            for index, motor in enumerate(online):
                entry = MotorInfoEntry(motor.address, motor.position, motor.begin, motor.end,
                                       motor.max_setup_speed, motor.max_move_speed,
                                       motor.max_acceleration, motor.is_fiz)
                out.append(MotorInfo([entry], index < len(online) - 1).encode())
        elif isinstance(message, GetDeviceGuid):
            out.append(DeviceGuid(self.settings.guid).encode())
        elif isinstance(message, GetLedStatus):
            out.append(LedStatus(*self.led, MessageType.RESPONSE).encode())
        elif isinstance(message, LedStatus) and message.message_type == MessageType.SET:
            self.led = (message.master_status, message.slave_status)
        elif isinstance(message, GetSoftwareId):
            out.append(SoftwareId(self.software_id, MessageType.RESPONSE).encode())
        elif isinstance(message, SoftwareId) and message.message_type == MessageType.SET:
            self.software_id = message.device_type
        elif isinstance(message, GetTrajectoryData):
            traj = self.playback.trajectory
            blocks = traj.to_message().blocks if traj else []
            out.append(TrajectoryData(blocks, MessageType.RESPONSE).encode())
        elif isinstance(message, TrajectoryData) and message.message_type == MessageType.SET:
            self._load(message, session)
        elif not self._handle_action(message, session):
            out.append(UnsupportedMessage(frame[:64]).encode())

    def _load(self, message: TrajectoryData, session: KosSession) -> None:
        try:
            traj = Trajectory.from_message(message)
            limits = {
                m.address: AxisLimits(m.begin, m.end, m.max_move_speed, m.max_acceleration)
                for m in self.motors.values() if m.online
            }
            validate(traj, limits)
        except ProtocolError as exc:
            LOG.info('rejecting TrajectoryData: %s', exc)
            self.error(ErrorCode.TRAJECTORY_DATA, 0, session)
            return
        self.playback = _Playback(trajectory=traj)
        self.playback_mode = traj.playback.playback_mode

    def _motor_for(self, address: int, session: KosSession) -> SimMotor | None:
        motor = self.motors.get(address)
        if motor is None or not motor.online:
            self.error(ErrorCode.INVALID_MOTOR_ADDRESS, address, session)
            return None
        return motor

    def _handle_action(self, message: Message, session: KosSession) -> bool:
        pb = self.playback
        if isinstance(message, SetPositionSpeedAcceleration):
            motor = self._motor_for(message.motor_address, session)
            if motor is None:
                return True
            values = (message.position, message.speed, message.acceleration)
            if not all(math.isfinite(v) for v in values):
                return True   # a real controller would reject garbage: never move on NaN
            if pb.phase not in ('idle', 'ready'):
                return True   # motors are under playback control
            target = message.position
            if isinstance(message, BumpPositionSpeedAcceleration):
                target = (motor.target if motor.target is not None
                          else motor.position) + message.position
            motor.command(target, message.speed, message.acceleration)
        elif isinstance(message, MarkBeginPosition):
            motor = self._motor_for(message.motor_address, session)
            if motor is not None:
                motor.mark_begin_raw = motor.position
        elif isinstance(message, MarkEndPosition):
            motor = self._motor_for(message.motor_address, session)
            if motor is not None:
                self._mark_end(motor)
        elif isinstance(message, ResetAxis):
            targets = (list(self.motors.values()) if message.motor_address == ALL_MOTORS
                       else [self._motor_for(message.motor_address, session)])
            for motor in targets:
                if motor is None:
                    continue
                motor.halt_now()
                motor.position = motor.begin = motor.end = 0.0
                motor.mark_begin_raw = None
                if message.motor_address != ALL_MOTORS:
                    self.broadcast(MotorCalibrated(motor.address, 0.0, 0.0))
        elif isinstance(message, TakePicture):
            if message.motor_address != ALL_MOTORS and message.motor_address not in self.motors:
                self.error(ErrorCode.INVALID_MOTOR_ADDRESS, message.motor_address, session)
            else:
                self.photos_taken += 1
        elif isinstance(message, SetupPlayback):
            self._setup(message, session)
        elif isinstance(message, StartPlayback):
            self._start(message, session)
        elif isinstance(message, StopPlayback):
            self.stop_playback()
        elif isinstance(message, RapidToFirstKeyFrame):
            if pb.trajectory is None or pb.phase not in ('idle', 'ready'):
                self.error(ErrorCode.RETURN_TO_FIRST_KEY_FRAME, 0, session)
            else:
                self._start_homing(then_start=False)
        elif isinstance(message, ResetDevice):
            self.reboot_requested = True
        else:
            return False
        return True

    def _mark_end(self, motor: SimMotor) -> None:
        begin_raw = motor.mark_begin_raw if motor.mark_begin_raw is not None else motor.begin
        span = motor.position - begin_raw
        if abs(span) < 1e-3:
            self.broadcast(ErrorStatus(ErrorCode.CALIBRATION, motor.address))
            motor.halt_now()
            motor.position = motor.begin = motor.end = 0.0
            motor.mark_begin_raw = None
            return
        # Document: afterwards MarkBegin is 0, MarkEnd is relative to it and the current
        # position equals MarkEnd.
        motor.halt_now()
        motor.begin, motor.end, motor.position = 0.0, span, span
        motor.mark_begin_raw = None
        self.broadcast(MotorCalibrated(motor.address, 0.0, span))

    def _setup(self, message: SetupPlayback, session: KosSession) -> None:
        pb = self.playback
        if pb.trajectory is None or pb.phase not in ('idle', 'ready'):
            self.error(ErrorCode.EXECUTE_MOVE, 0, session)
            return
        if not self._playback_preconditions(message.direction, session):
            return
        pb.setup_done = True
        if message.delay_return:
            pb.phase = 'ready'
            pb.homing_targets = {}
            self._playback_note(PlaybackState.SETUP_COMPLETED)
            pb.homing_owed = True
        else:
            self._start_homing(then_start=False)

    def _playback_preconditions(self, direction: int, session: KosSession) -> bool:
        traj = self.playback.trajectory
        assert traj is not None
        if direction != 0 and traj.playback.playback_mode != PlaybackMode.LIVE_MOTION:
            self.error(ErrorCode.EXECUTE_MOVE, 0, session)   # no reverse in a time lapse
            return False
        for address in traj.axes:
            motor = self.motors.get(address)
            if motor is None or not motor.online or not motor.calibrated:
                self.error(ErrorCode.EXECUTE_MOVE, 0, session)   # (*) code: address 0
                return False
        return True

    def _start(self, message: StartPlayback, session: KosSession) -> None:
        pb = self.playback
        if pb.trajectory is None or pb.phase not in ('idle', 'ready'):
            self.error(ErrorCode.EXECUTE_MOVE, 0, session)
            return
        if not self._playback_preconditions(message.direction, session):
            return
        pl = pb.trajectory.playback
        pb.loops_left = max(pl.loop_after_reverse, pl.loop_after_rapid_reverse)
        pb.loop_forever = pb.loops_left == 255
        pb.photos = 0
        if pb.phase == 'ready' and not pb.homing_owed:
            self._begin_after_setup()        # set up and already at the first key frame
        else:
            self._start_homing(then_start=True)   # no setup, or DelayReturn

    # -------------------------------------------------------------------- replies
    def device_info(self) -> DeviceInfo:
        fw = self.settings.firmware
        pb = self.playback
        remaining = 0.0
        if pb.phase == 'delay':
            remaining = (max(pb.start_at - time.time(), 0.0) if pb.start_at is not None
                         else max(pb.pass_length - pb.phase_time, 0.0))
        return DeviceInfo(self.settings.device_type, 0, int(self.playback_mode), pb.status,
                          *fw, 0, 0, self.password, self.aux_input, remaining, pb.elapsed,
                          pb.photos)

    def network_info(self) -> NetworkInfo:
        return NetworkInfo(False, bytes.fromhex('02004b4f5301'), 0x7F000001, 0xFF000000, 0,
                           self.settings.device_type, 0, MessageType.RESPONSE)

    # ------------------------------------------------------------- fault injection
    def set_motor_online(self, address: int, online: bool) -> None:
        with self.lock:
            motor = self.motors[address]
            motor.online = online
            if not online:
                motor.halt_now()
                if self.playback.trajectory and address in self.playback.trajectory.axes \
                        and self.playback.phase not in ('idle', 'ready'):
                    self.broadcast(ErrorStatus(ErrorCode.EXECUTE_MOVE, 0))
                    self.stop_playback()
            self.broadcast(MotorStatus([MotorStatusEntry(
                address, online, 1 if motor.is_fiz else 0, motor.max_setup_speed,
                motor.max_move_speed, motor.max_acceleration)]))

    def inject_axis_fault(self, address: int, code: int = ErrorCode.AXIS_FAULT) -> None:
        """ErrorStatus with "axis will be reset": the axis stops and loses calibration."""
        with self.lock:
            motor = self.motors[address]
            if self.playback.phase not in ('idle', 'ready'):
                self.stop_playback()
            motor.halt_now()
            self.broadcast(ErrorStatus(code, address))
            motor.begin = motor.end = 0.0
            motor.mark_begin_raw = None


class KosSession:
    """One TCP connection or USB HID link: framing, lock state, keep-alive, reply queue."""

    def __init__(self, device: SimulatedRig, usb: bool = False) -> None:
        self.device = device
        self.usb = usb
        self.parser = FrameParser()
        self.unlocked = usb            # USB has no password messages
        self.usb_keepalives = 0
        self.outbox: list[bytes] = []
        self.last_rx = time.monotonic()
        self.malformed = 0
        with device.lock:
            device.sessions.append(self)

    def on_bytes(self, data: bytes) -> bytes:
        self.last_rx = time.monotonic()
        device = self.device
        device.advance()
        with device.lock:
            for frame in self.parser.feed(data):
                if self.usb and frame == USB_KEEPALIVE:
                    self.usb_keepalives += 1
                    continue
                try:
                    message = decode(frame)
                except ProtocolError as exc:
                    self.malformed += 1
                    LOG.info('malformed frame (%s); answering UnsupportedMessage', exc)
                    if self.unlocked:
                        self.outbox.append(UnsupportedMessage(frame[:64]).encode())
                    continue
                device.handle(message, frame, self)
            return self._drain()

    def poll(self) -> bytes:
        device = self.device
        if time.monotonic() - self.last_rx > device.settings.keepalive_timeout:
            LOG.info('no message for %.1f s: dropping the connection (keep-alive)',
                     device.settings.keepalive_timeout)
            raise ConnectionAbortedError('kOS keep-alive expired')
        if device.reboot_requested:
            raise ConnectionAbortedError('device reboot')
        device.advance()
        with device.lock:
            return self._drain()

    def _drain(self) -> bytes:
        data = b''.join(self.outbox)
        self.outbox.clear()
        return data

    def on_disconnect(self) -> None:
        with self.device.lock:
            if self in self.device.sessions:
                self.device.sessions.remove(self)


class SimHidDevice:
    """The simulated device seen through USB HID, with the methods of `hid.device`.

    `write` takes output reports (report ID 0x01 + message bytes, zero padded) and feeds the
    reassembled kOS bytes to a USB session of the shared `SimulatedRig`; `read` returns one
    input report (report ID first, padded to `report_size`) per call, polling the session
    for notifications while it waits. A session silent for the keep-alive timeout, or a
    device unplugged with `unplug()`, makes `read`/`write` raise OSError like hidapi does.
    """

    def __init__(self, device: SimulatedRig, report_size: int = REPORT_SIZE) -> None:
        self.device = device
        self.report_size = report_size
        self.session: KosSession | None = None
        self.reports_written: list[bytes] = []   # raw output reports, for inspection
        self.reports_read: list[bytes] = []
        self._reassembler = ReportReassembler()
        self._parser = FrameParser()
        self._inbox: list[bytes] = []
        self._lock = threading.Lock()
        self._unplugged = False

    # -- hid.device methods
    def open(self, vendor_id: int = 0, product_id: int = 0,
             serial_number: str | None = None) -> None:
        self._open()

    def open_path(self, path: bytes) -> None:
        self._open()

    def _open(self) -> None:
        if self._unplugged:
            raise OSError('open failed')
        self.close()
        self.session = KosSession(self.device, usb=True)

    def close(self) -> None:
        session, self.session = self.session, None
        if session is not None:
            session.on_disconnect()
        self._reassembler.reset()
        self._parser.reset()
        self._inbox.clear()

    def write(self, buff) -> int:
        report = bytes(buff)
        session = self._session()
        with self._lock:
            self.reports_written.append(report)
            self._queue(session.on_bytes(self._reassembler.feed(report)))
        return len(report)

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        deadline = time.monotonic() + timeout_ms / 1000.0
        while True:
            session = self._session()
            with self._lock:
                if not self._inbox:
                    try:
                        self._queue(session.poll())
                    except ConnectionAbortedError as exc:
                        self.close()
                        raise OSError(f'read error ({exc})') from exc
                if self._inbox:
                    report = self._inbox.pop(0)
                    self.reports_read.append(report)
                    return list(report[:max_length])
            if time.monotonic() >= deadline:
                return []
            time.sleep(0.002)

    # -- test helpers
    def unplug(self) -> None:
        """The cable is pulled: reads and writes fail, open fails until `plug_in()`."""
        self._unplugged = True
        self.close()

    def plug_in(self) -> None:
        self._unplugged = False

    def inject_report(self, report: bytes) -> None:
        """Queue a raw input report (foreign report IDs, garbage)."""
        with self._lock:
            self._inbox.append(bytes(report))

    def _session(self) -> KosSession:
        if self.session is None:
            raise OSError('read error' if self._unplugged else 'device not open')
        return self.session

    def _queue(self, data: bytes) -> None:
        for frame in self._parser.feed(data):
            self._inbox.extend(encode_reports(frame, self.report_size))


class KosSimulator:
    """Device + TCP server + discovery beacon + optional control port."""

    def __init__(self, settings: SimSettings, port: int = 0, discovery_port: int = 0,
                 control_port: int | None = None) -> None:
        self.device = SimulatedRig(settings)
        self.server = TcpSimServer(lambda: KosSession(self.device), port=port)
        self.discovery_port = discovery_port
        self.control_port_requested = control_port
        self.control_port = 0
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._control_server: ControlServer | None = None
        self.controls = self._make_controls()

    @property
    def port(self) -> int:
        return self.server.port

    def start(self) -> KosSimulator:
        self.server.start()
        self._spawn(self._background, 'kos-sim-background')
        if self.control_port_requested is not None:
            self._control_server = ControlServer(self.controls,
                                                 self.control_port_requested).start()
            self.control_port = self._control_server.port
        return self

    def stop(self) -> None:
        self._stop.set()
        self.server.stop()
        if self._control_server is not None:
            self._control_server.stop()
        for thread in self._threads:
            thread.join(timeout=2.0)

    def _spawn(self, target, name: str) -> None:
        thread = threading.Thread(target=target, name=name, daemon=True)
        thread.start()
        self._threads.append(thread)

    def _background(self) -> None:
        """Keep physics running without clients, beacon NetworkInfo, handle reboots."""
        next_beacon = time.monotonic()
        beacon = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            while not self._stop.wait(0.02):
                self.device.advance()
                if self.device.reboot_requested:
                    self.server.drop_link()
                    with self.device.lock:
                        self.device.reboot_requested = False
                        self.device.playback = _Playback()
                now = time.monotonic()
                if self.discovery_port and now >= next_beacon:
                    next_beacon = now + DISCOVERY_PERIOD_S / max(self.device.settings.time_scale,
                                                                 1.0)
                    if self.server.client_count == 0:
                        data = self.device.network_info().encode()
                        # Loopback only: never the limited broadcast the document describes.
                        with contextlib.suppress(OSError):
                            beacon.sendto(data, ('127.0.0.1', self.discovery_port))
        finally:
            beacon.close()

    # ------------------------------------------------------------- control verbs
    def command(self, line: str) -> str:
        """Run one control request (shared verbs plus kOS's own); return the answer line."""
        return self.controls.execute(line)

    def _make_controls(self) -> SimControl:
        device = self.device
        control = SimControl(
            'kessler_kos_sim', self.state, links=[self.server],
            no_nack='kOS answers a bad request with ErrorStatus (see fault and error), '
                    'it has no negative acknowledge',
            fault=self._fault, fault_names=('axis',), clear_device=self._clear_injected)
        control.add_verb('offline', lambda a: device.set_motor_online(int(a[0]), False),
                         'offline MOTOR')
        control.add_verb('online', lambda a: device.set_motor_online(int(a[0]), True),
                         'online MOTOR')
        control.add_verb('error', self._error, 'error CODE [MOTOR] (ErrorStatus, no reset)')
        control.add_verb('aux', self._aux, 'aux BITS (AuxInputStatus)')
        return control

    def _fault(self, args: list[str]) -> None:
        """``fault axis MOTOR`` or ``fault CODE MOTOR``: ErrorStatus with axis reset."""
        code = ErrorCode.AXIS_FAULT if args[0].lower() == 'axis' else int(args[0], 0)
        self.device.inject_axis_fault(int(args[1]) if len(args) > 1 else 1, code)

    def _error(self, args: list[str]) -> None:
        with self.device.lock:
            self.device.broadcast(ErrorStatus(int(args[0]), int(args[1]) if len(args) > 1
                                              else 0))

    def _aux(self, args: list[str]) -> None:
        bits = int(args[0], 0)
        with self.device.lock:
            self.device.aux_input = bits
            self.device.broadcast(AuxInputStatus(bits))

    def _clear_injected(self) -> None:
        for address, motor in self.device.motors.items():
            if not motor.online:
                self.device.set_motor_online(address, True)

    def state(self) -> dict:
        """The ``state`` answer: motors (rotations) by role, playback phase, photos."""
        device = self.device
        with device.lock:
            return {
                'axes': {m.role: {**m.snapshot(), 'address': m.address, 'begin': m.begin,
                                  'end': m.end, 'online': m.online}
                         for m in device.motors.values()},
                'phase': device.playback.phase, 'photos': device.photos_taken,
                'clients': self.server.client_count, 'led': list(device.led),
                'aux_input': device.aux_input,
            }


#: one request to a running kessler_kos_sim's TCP console (the shared protocol)
control = control_request


def build_arg_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='kessler_kos_sim',
        description='Kessler kOS CineShooter simulator on TCP 127.0.0.1 (kOS network protocol).')
    parser.add_argument('--port', type=int, default=DEFAULT_TCP_PORT,
                        help='TCP port on 127.0.0.1 (0 = any free port; default 5520)')
    parser.add_argument('--password', default='', help='device password (default empty)')
    parser.add_argument('--motors', default='slider,pan,tilt',
                        help='comma-separated motor roles in address order '
                             '(slider, pan, tilt, focus, zoom); default slider,pan,tilt')
    parser.add_argument('--precalibrated', action='store_true',
                        help='start with every motor calibrated over a default range')
    parser.add_argument('--time-scale', type=float, default=1.0,
                        help='simulated seconds per wall-clock second (default 1)')
    parser.add_argument('--keepalive-timeout', type=float, default=KEEPALIVE_DROP_S,
                        help='drop a connection silent for this many wall seconds (30)')
    parser.add_argument('--discovery-port', type=int, default=DEFAULT_TCP_PORT,
                        help='UDP port NetworkInfo beacons go to on 127.0.0.1 (0 = off)')
    parser.add_argument('--control-port', type=int, default=0,
                        help='control console on 127.0.0.1 (0 = any free port, -1 = none); '
                             'the same verbs are read on stdin')
    parser.add_argument('--verbose', action='store_true')
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_arg_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format='%(asctime)s %(name)s: %(message)s')
    roles = tuple(r.strip().lower() for r in args.motors.split(',') if r.strip())
    unknown = [r for r in roles if r not in DOCUMENTED_MAXIMA]
    if not roles or unknown or len(roles) > MOTOR_ADDRESS_MAX - MOTOR_ADDRESS_MIN + 1:
        print(f'kessler_kos_sim: --motors must list 1..10 of {sorted(DOCUMENTED_MAXIMA)}, '
              f'got {args.motors!r}', file=sys.stderr)
        return 2
    if args.time_scale <= 0 or args.keepalive_timeout <= 0:
        print('kessler_kos_sim: --time-scale and --keepalive-timeout must be > 0',
              file=sys.stderr)
        return 2
    settings = SimSettings(password=args.password, motors=roles,
                           precalibrated=args.precalibrated, time_scale=args.time_scale,
                           keepalive_timeout=args.keepalive_timeout)
    sim = KosSimulator(settings, port=args.port, discovery_port=args.discovery_port)
    try:
        sim.start()
    except OSError as exc:
        print(f'kessler_kos_sim: cannot listen on 127.0.0.1:{args.port}: {exc}',
              file=sys.stderr)
        return 1
    try:
        run_simulator(sim.controls, {'port': sim.port, 'motors': list(roles)},
                      args.control_port)
    finally:
        sim.stop()
    return 0


if __name__ == '__main__':
    sys.exit(main())
