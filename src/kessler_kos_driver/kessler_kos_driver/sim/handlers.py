"""kOS simulator: the handlers of the client messages (calibration, motion, playback)."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from gimbal_driver_common.sim_requests import RequestFaults

from ..protocol import (
    ALL_MOTORS,
    BumpPositionSpeedAcceleration,
    DeviceGuid,
    DeviceInfo,
    DevicePassword,
    ErrorCode,
    ErrorStatus,
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
    NetworkInfo,
    PlaybackMode,
    PlaybackState,
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
    validate,
)
from ..protocol.trajectory import AxisLimits
from .motor import ALLOWED_WHILE_LOCKED, SimMotor, SimSettings, _Playback

if TYPE_CHECKING:
    from .transport import KosSession

LOG = logging.getLogger('kessler_kos_sim')

#: the client messages the device answers, and the motion messages it acts on without an
#: answer (``mute``/``delay``/``ignore`` take these names; a delay of an unanswered
#: message holds nothing)
REQUESTS = tuple(message.__name__ for message in (
    GetDeviceGuid, GetDeviceInfo, GetLedStatus, GetMotorInfo, GetNetworkInfo, GetSoftwareId,
    GetTrajectoryData, SetPositionSpeedAcceleration, StopPlayback, StartPlayback,
    RapidToFirstKeyFrame))


class _StartHoming(Protocol):
    """SimulatedRig._start_homing, which the handlers call with its keyword."""

    def __call__(self, then_start: bool) -> None: ...


class MessageHandlers:
    """The client messages of :class:`~.model.SimulatedRig`, a base of it whose state they
    read and change."""

    # The rig's state and helpers the handlers use (SimulatedRig defines each).
    settings: SimSettings
    password: str
    motors: dict[int, SimMotor]
    playback: _Playback
    playback_mode: int
    led: tuple[int, int]
    software_id: int
    frames_received: int
    photos_taken: int
    reboot_requested: bool
    request_faults: RequestFaults
    device_info: Callable[[], DeviceInfo]
    network_info: Callable[[], NetworkInfo]
    error: Callable[[int, int, KosSession | None], None]
    broadcast: Callable[[Message], None]
    stop_playback: Callable[[], None]
    _playback_note: Callable[[int], None]
    _start_homing: _StartHoming
    _begin_after_setup: Callable[[], None]

    # ------------------------------------------------------------------ handlers
    def handle(self, message: Message, frame: bytes, session: KosSession) -> None:
        """Apply one decoded client message; replies go to session.outbox."""
        self.frames_received += 1
        if self.request_faults.muted(type(message).__name__):
            return  # mute: received and dropped, never acted on or answered
        if self.request_faults.ignored(type(message).__name__) and \
                not type(message).__name__.startswith('Get'):
            return  # ignore: taken and not acted on (kOS answers a command with nothing)
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
