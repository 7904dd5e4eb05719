"""The kOS client's commands, in the device's units (rotations): motion, device settings,
calibration and playback (no ROS).

A mixin of :class:`~.client.KosClient`, which gives it the session: ``send``, ``request``,
``barrier``, ``_checked`` (an action followed by a barrier, raising the device's error),
``motor``, ``refresh_motors``, ``wait_for``, ``_errors_since`` and the state (``motors``,
``playback``, ``errors``, ``_seq``, ``_lock``). Limits are the adapter's to check
(``device.py``, in SI) before it calls these.
"""

from __future__ import annotations

import math

from .client_types import CommandRejected, DeviceTimeout
from .protocol import (
    ALL_MOTORS,
    PLAYBACK_RUNNING_STATES,
    BumpPositionSpeedAcceleration,
    ErrorCode,
    GetLedStatus,
    GetSoftwareId,
    GetTrajectoryData,
    LedState,
    LedStatus,
    MarkBeginPosition,
    MarkEndPosition,
    ProtocolError,
    RapidToFirstKeyFrame,
    ResetAxis,
    SetPositionSpeedAcceleration,
    SetupPlayback,
    SoftwareId,
    StartPlayback,
    StopPlayback,
    TakePicture,
    Trajectory,
    TrajectoryData,
    validate,
)


class KosCommands:
    """Motion, settings, calibration and playback messages of a kOS session."""

    # Motor messages in rotations, unchecked: the adapter (device.py) checks every target
    # and speed against the motor's range and maxima, in SI, before calling these.
    @property
    def playback_running(self) -> bool:
        """True while the device executes a move (it then owns the motors)."""
        return self.playback.status in PLAYBACK_RUNNING_STATES

    def move_to(self, address: int, position: float, speed: float,
                acceleration: float | None = None) -> None:
        """Absolute move in rotations (SetPositionSpeedAcceleration)."""
        motor = self.motor(address)
        accel = motor.max_acceleration if acceleration is None else acceleration
        self.send(SetPositionSpeedAcceleration(address, position, speed, accel))

    def bump(self, address: int, delta: float, speed: float,
             acceleration: float | None = None) -> None:
        """Relative move (BumpPositionSpeedAcceleration), refused when it would end outside
        the range (the adapter has no relative move: this is its only check)."""
        motor = self.motor(address)
        accel = motor.max_acceleration if acceleration is None else acceleration
        lo, hi = motor.travel()
        target = motor.position + delta
        if not math.isfinite(delta) or not lo <= target <= hi:
            raise CommandRejected(f'motor {address}: bump by {delta:.4f} rot would end at '
                                  f'{target:.4f}, outside [{lo:.4f}, {hi:.4f}]')
        self.send(BumpPositionSpeedAcceleration(address, delta, speed, accel))

    def jog(self, address: int, velocity: float, acceleration: float | None = None) -> None:
        """Move at `velocity` rot/s toward the end of travel (0 stops)."""
        motor = self.motor(address)
        if velocity == 0:
            self.stop_motor(address)
            return
        accel = motor.max_acceleration if acceleration is None else acceleration
        lo, hi = motor.travel()
        self.send(SetPositionSpeedAcceleration(address, hi if velocity > 0 else lo,
                                               abs(velocity), accel))

    def stop_motor(self, address: int) -> None:
        motor = self.motor(address)
        self.send(SetPositionSpeedAcceleration(address, motor.position, 0.0,
                                               motor.max_acceleration))

    def stop_all(self) -> None:
        """StopPlayback (stops every motor immediately) and speed 0 for each motor."""
        self.send(StopPlayback())
        for address, motor in list(self.motors.items()):
            if motor.online:
                self.send(SetPositionSpeedAcceleration(address, motor.position, 0.0,
                                                       motor.max_acceleration))

    def take_picture(self, exposure: float = 0.0) -> None:
        if not math.isfinite(exposure) or exposure < 0:
            raise CommandRejected(f'exposure must be >= 0 s, got {exposure}')
        self._checked(TakePicture(ALL_MOTORS, exposure), 'TakePicture')

    # ------------------------------------------------------------ device settings
    def led_status(self) -> tuple[int, int]:
        """(Get)LEDStatus: (master, slave), each a LedState (0 off, 1 on, 2/3 blink)."""
        reply = self.request(GetLedStatus())
        assert isinstance(reply, LedStatus)
        return reply.master_status, reply.slave_status

    def set_led_status(self, master: int, slave: int) -> tuple[int, int]:
        """(Set)LEDStatus, then read the LEDs back (a Set has no reply)."""
        allowed = [int(s) for s in LedState]
        for name, value in (('master', master), ('slave', slave)):
            if value not in allowed:
                raise CommandRejected(f'{name} LED status {value!r} is not one of {allowed} '
                                      '(0 off, 1 on, 2 slow blink, 3 fast blink)')
        self.send(LedStatus(int(master), int(slave)))
        return self.led_status()

    def software_id(self) -> int:
        """(Get)SoftwareID: the platform id of the last client that used the device."""
        reply = self.request(GetSoftwareId())
        assert isinstance(reply, SoftwareId)
        return reply.device_type

    def set_software_id(self, platform: int) -> int:
        """(Set)SoftwareID, read back; the caller decides whether writing it is allowed."""
        if isinstance(platform, bool) or not isinstance(platform, int) \
                or not 0 <= platform <= 0xFF:
            raise CommandRejected(f'SoftwareID must be an integer 0..255, got {platform!r}')
        self.send(SoftwareId(platform))
        return self.software_id()

    # ------------------------------------------------------------- calibration
    def mark_begin(self, address: int) -> None:
        self.motor(address)
        self._checked(MarkBeginPosition(address), f'MarkBeginPosition motor {address}')

    def _await_calibrated(self, address: int, seq0: int, timeout: float, what: str) -> None:
        key = -2000 - address
        if not self.wait_for(lambda: self._seq.get(key, 0) > seq0, timeout):
            errors = [e for e in self.errors if e.motor_address == address]
            reason = f' (device error {errors[-1].code}: {errors[-1].description})' \
                if errors else ''
            raise DeviceTimeout(f'{what}: no MotorCalibrated notification for motor '
                                f'{address}{reason}')

    def mark_end(self, address: int, timeout: float | None = None) -> tuple[float, float]:
        """MarkEndPosition; returns (begin, end) from the MotorCalibrated notification."""
        self.motor(address)
        with self._lock:
            seq0 = self._seq.get(-2000 - address, 0)
        marker = self.error_total
        self.send(MarkEndPosition(address))
        self.barrier()
        failed = [e for e in self._errors_since(marker) if e.code == ErrorCode.CALIBRATION]
        if failed:
            raise CommandRejected(f'motor {address}: calibration failed (error 14: the end '
                                  'mark must differ from the begin mark); the axis was reset')
        self._await_calibrated(address, seq0, timeout or self.reply_timeout, 'MarkEndPosition')
        motor = self.motors[address]
        return motor.begin_position, motor.end_position

    def reset_axis(self, address: int, timeout: float | None = None) -> None:
        """Clear calibration (address 0: every axis, no notification expected)."""
        if address != ALL_MOTORS:
            self.motor(address)
        with self._lock:
            seq0 = self._seq.get(-2000 - address, 0)
        self.send(ResetAxis(address))
        if address == ALL_MOTORS:
            self.barrier()
            self.refresh_motors()
            return
        self._await_calibrated(address, seq0, timeout or self.reply_timeout, 'ResetAxis')

    # ---------------------------------------------------------------- playback
    def load_trajectory(self, trajectory: Trajectory) -> None:
        """Validate against the motors' calibration and maxima, send, and confirm."""
        self.refresh_motors()
        limits = {a: m.limits() for a, m in self.motors.items() if m.online}
        try:
            validate(trajectory, limits)
        except ProtocolError as exc:
            raise CommandRejected(f'trajectory refused before sending: {exc}') from exc
        with self._lock:
            self.playback.loaded = False
            self.playback.set_up = False
            self.playback.history = []
        marker = self.error_total
        self.send(trajectory.to_message())
        echo = self.request(GetTrajectoryData())   # barrier + confirmation
        errors = self._errors_since(marker)
        if errors:
            raise CommandRejected(f'device rejected the trajectory: error {errors[0].code} '
                                  f'({errors[0].description})')
        expected = len(trajectory.to_message().blocks)
        if not isinstance(echo, TrajectoryData) or len(echo.blocks) != expected:
            raise CommandRejected('device did not store the trajectory (GetTrajectoryData '
                                  'returned a different move)')
        with self._lock:
            self.playback.loaded = True

    def setup_playback(self, delay_return: bool = False) -> None:
        if not self.playback.loaded:
            raise CommandRejected('no trajectory loaded (a FullStop consumes the move; load '
                                  'it again)')
        self._checked(SetupPlayback(0, 0.0, delay_return), 'SetupPlayback')

    def start_playback(self) -> None:
        if not self.playback.loaded:
            raise CommandRejected('no trajectory loaded (a FullStop consumes the move; load '
                                  'it again)')
        self._checked(StartPlayback(0, 0.0), 'StartPlayback')

    def stop_playback(self) -> None:
        self.send(StopPlayback())

    def rapid_to_first_key_frame(self) -> None:
        if not self.playback.loaded:
            raise CommandRejected('RapidToFirstKeyFrame needs a loaded trajectory')
        self._checked(RapidToFirstKeyFrame(), 'RapidToFirstKeyFrame')

    def wait_playback(self, status: int, timeout: float) -> bool:
        """Wait until a PlaybackStatus `status` has been seen since the last load."""
        return self.wait_for(lambda: status in self.playback.history, timeout)
