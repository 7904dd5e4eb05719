"""kOS simulator: the device model (motors, playback over time, replies, faults)."""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING

from gimbal_driver_common.sim_requests import RequestFaults

from ..protocol import (
    DOCUMENTED_MAXIMA,
    DeviceInfo,
    ErrorCode,
    ErrorStatus,
    Message,
    MessageType,
    MotorPosition,
    MotorStatus,
    MotorStatusEntry,
    NetworkInfo,
    PlaybackMode,
    PlaybackState,
    PlaybackStatus,
    position_at,
)
from .handlers import MessageHandlers
from .motor import DEFAULT_RANGES, MAX_CATCH_UP_S, PHYSICS_STEP_S, SimMotor, SimSettings, _Playback

if TYPE_CHECKING:
    from .transport import KosSession


class SimulatedRig(MessageHandlers):
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
        #: requests never answered (``mute``: received, dropped) or answered late
        #: (``delay``: the session holds the reply), by message name (:data:`REQUESTS`)
        self.request_faults = RequestFaults()

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
            self._set_curve_positions()

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
        traj = self.playback.trajectory
        assert traj is not None  # a time-lapse frame is timed only while one plays
        tl = traj.timelapse
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
        pb.curve_dt += dt
        fraction = min(pb.move_time / pb.pass_length, 1.0) if pb.pass_length > 0 else 1.0
        pb.elapsed = fraction if pb.direction > 0 else 1.0 - fraction
        if traj.playback.playback_mode == PlaybackMode.TIMELAPSE_CONTINUOUS:
            due = int(pb.move_time / self._frame_time())
            while pb.photos < traj.timelapse.pre_move_photos + min(
                    due, traj.timelapse.move_photos):
                self._take_photo()
        if fraction < 1.0:
            return  # the axes are set on the curve once per advance (_set_curve_positions)
        self._set_curve_positions()
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

    def _set_curve_positions(self) -> None:
        """Put the playing axes where the curve is now, at the speed since they were last put.

        Once per :meth:`advance` and at the end of a pass, not each physics step: the curve
        gives the position at any time, and evaluating it (a Bezier inverted by bisection)
        each 2 ms step cost 0.3-0.8 ms, so at the tests' time scale of 20 the simulator
        needed several cores to keep up and ran as slow as the machine (docs/testing.md).
        """
        pb = self.playback
        if pb.phase != 'play' or pb.trajectory is None or pb.curve_dt <= 0.0:
            return
        for address, position in self._curve_positions(pb.elapsed).items():
            motor = self.motors[address]
            motor.velocity = (position - motor.position) / pb.curve_dt
            motor.position = position
        pb.curve_dt = 0.0

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
