"""The kOS client's commands, in the device's units (rotations): motion, device settings,
calibration and playback (no ROS).

A part of :class:`~.client.KosClient` (its ``commands`` attribute), handed the session's
messaging (:class:`MessageLink`: ``send``, ``request``, ``barrier``, ``refresh_motors``)
and the state the notifications keep (:class:`~.client_state.KosState`). Limits are the
adapter's to check (``device.py``, in SI) before it calls these.
"""

from __future__ import annotations

import math
from typing import Protocol

from gimbal_driver_common.errors import EverySteps

from .client_state import KosState, calibrated_key
from .client_types import CommandRejected, DeviceTimeout, MotorState
from .protocol import (
    ALL_MOTORS,
    BumpPositionSpeedAcceleration,
    ErrorCode,
    GetLedStatus,
    GetSoftwareId,
    GetTrajectoryData,
    LedState,
    LedStatus,
    MarkBeginPosition,
    MarkEndPosition,
    Message,
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


class MessageLink(Protocol):
    """What the commands use of the session (:class:`~.client.KosClient`)."""

    reply_timeout: float

    def send(self, message: Message) -> None:
        """Encode (checks ranges) and send one message."""

    def request(self, message: Message, timeout: float | None = None) -> Message:
        """Send a Get and wait for its response."""

    def barrier(self) -> None:
        """Wait until the device has handled everything sent so far."""

    def refresh_motors(self) -> dict[int, MotorState]:
        """Read MotorInfo again (the state's motors)."""


class KosCommands:
    """Motion, settings, calibration and playback messages of a kOS session."""

    def __init__(self, link: MessageLink, state: KosState) -> None:
        self._link = link
        self._state = state

    def send(self, message: Message) -> None:
        self._link.send(message)

    def motor(self, address: int) -> MotorState:
        return self._state.motor(address)

    def _checked(self, action: Message, what: str) -> None:
        """Send an action followed by a barrier; raise if the device reported an error."""
        marker = self._state.error_total
        self.send(action)
        self._link.barrier()
        errors = self._state.errors_since(marker)
        if errors:
            first = errors[0]
            raise CommandRejected(f'{what}: device reported error {first.code} '
                                  f'({first.description}, motor {first.motor_address})')

    # Motor messages in rotations, unchecked: the adapter (device.py) checks every target
    # and speed against the motor's range and maxima, in SI, before calling these.

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
        """Speed 0 for each motor, then StopPlayback (which also stops every motor): every
        message is written whatever the one before did; the failures are raised after."""
        steps = EverySteps()
        for address, motor in list(self._state.motors.items()):
            if motor.online:
                steps.run(self.send, SetPositionSpeedAcceleration(
                    address, motor.position, 0.0, motor.max_acceleration))
        steps.run(self.send, StopPlayback())
        steps.raise_errors()

    def take_picture(self, exposure: float = 0.0) -> None:
        if not math.isfinite(exposure) or exposure < 0:
            raise CommandRejected(f'exposure must be >= 0 s, got {exposure}')
        self._checked(TakePicture(ALL_MOTORS, exposure), 'TakePicture')

    # ------------------------------------------------------------ device settings
    def led_status(self) -> tuple[int, int]:
        """(Get)LEDStatus: (master, slave), each a LedState (0 off, 1 on, 2/3 blink)."""
        reply = self._link.request(GetLedStatus())
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
        reply = self._link.request(GetSoftwareId())
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
        state = self._state
        if not state.wait_for(lambda: state.count(calibrated_key(address)) > seq0, timeout):
            errors = [e for e in state.errors if e.motor_address == address]
            reason = f' (device error {errors[-1].code}: {errors[-1].description})' \
                if errors else ''
            raise DeviceTimeout(f'{what}: no MotorCalibrated notification for motor '
                                f'{address}{reason}')

    def mark_end(self, address: int, timeout: float | None = None) -> tuple[float, float]:
        """MarkEndPosition; returns (begin, end) from the MotorCalibrated notification."""
        self.motor(address)
        state = self._state
        seq0 = state.count(calibrated_key(address))
        marker = state.error_total
        self.send(MarkEndPosition(address))
        self._link.barrier()
        failed = [e for e in state.errors_since(marker) if e.code == ErrorCode.CALIBRATION]
        if failed:
            raise CommandRejected(f'motor {address}: calibration failed (error 14: the end '
                                  'mark must differ from the begin mark); the axis was reset')
        self._await_calibrated(address, seq0, timeout or self._link.reply_timeout,
                               'MarkEndPosition')
        motor = state.motors[address]
        return motor.begin_position, motor.end_position

    def reset_axis(self, address: int, timeout: float | None = None) -> None:
        """Clear calibration (address 0: every axis, no notification expected)."""
        if address != ALL_MOTORS:
            self.motor(address)
        seq0 = self._state.count(calibrated_key(address))
        self.send(ResetAxis(address))
        if address == ALL_MOTORS:
            self._link.barrier()
            self._link.refresh_motors()
            return
        self._await_calibrated(address, seq0, timeout or self._link.reply_timeout, 'ResetAxis')

    # ---------------------------------------------------------------- playback
    def load_trajectory(self, trajectory: Trajectory) -> None:
        """Validate against the motors' calibration and maxima, send, and confirm."""
        state = self._state
        self._link.refresh_motors()
        limits = {a: m.limits() for a, m in state.motors.items() if m.online}
        try:
            validate(trajectory, limits)
        except ProtocolError as exc:
            raise CommandRejected(f'trajectory refused before sending: {exc}') from exc
        with state.lock:
            state.playback.loaded = False
            state.playback.set_up = False
            state.playback.history = []
        marker = state.error_total
        self.send(trajectory.to_message())
        echo = self._link.request(GetTrajectoryData())   # barrier + confirmation
        errors = state.errors_since(marker)
        if errors:
            raise CommandRejected(f'device rejected the trajectory: error {errors[0].code} '
                                  f'({errors[0].description})')
        expected = len(trajectory.to_message().blocks)
        if not isinstance(echo, TrajectoryData) or len(echo.blocks) != expected:
            raise CommandRejected('device did not store the trajectory (GetTrajectoryData '
                                  'returned a different move)')
        with state.lock:
            state.playback.loaded = True

    def setup_playback(self, delay_return: bool = False) -> None:
        if not self._state.playback.loaded:
            raise CommandRejected('no trajectory loaded (a FullStop consumes the move; load '
                                  'it again)')
        self._checked(SetupPlayback(0, 0.0, delay_return), 'SetupPlayback')

    def start_playback(self) -> None:
        if not self._state.playback.loaded:
            raise CommandRejected('no trajectory loaded (a FullStop consumes the move; load '
                                  'it again)')
        self._checked(StartPlayback(0, 0.0), 'StartPlayback')

    def stop_playback(self) -> None:
        self.send(StopPlayback())

    def rapid_to_first_key_frame(self) -> None:
        if not self._state.playback.loaded:
            raise CommandRejected('RapidToFirstKeyFrame needs a loaded trajectory')
        self._checked(RapidToFirstKeyFrame(), 'RapidToFirstKeyFrame')

    def wait_playback(self, status: int, timeout: float) -> bool:
        """Wait until a PlaybackStatus `status` has been seen since the last load."""
        state = self._state
        return state.wait_for(lambda: status in state.playback.history, timeout)
