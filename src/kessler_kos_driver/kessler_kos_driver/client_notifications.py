"""The kOS client's notification handling (no ROS): every message the session reads is
dispatched here, on the reader thread, into the session's state (motors, playback, errors,
aux inputs: :class:`~.client_state.KosState`), waking the waiters and calling the
adapter's callbacks.

A part of :class:`~.client.KosClient` (its ``notifications`` attribute), kept apart so the
session (connection, messaging, reader tick) reads in one sitting; it is handed the state
it updates and owns the ``on_*`` callbacks the adapter sets.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

from .client_state import ERROR_KEY, PLAYBACK_KEY, KosState, calibrated_key, position_key
from .client_types import ErrorEvent, MotorState
from .protocol import (
    AuxInputStatus,
    ErrorStatus,
    Message,
    MotorCalibrated,
    MotorInfo,
    MotorPosition,
    MotorStatus,
    PlaybackState,
    PlaybackStatus,
    UnknownMessage,
    UnsupportedMessage,
    describe_error,
)
from .protocol.messages import MotorInfoEntry

#: the client's logger: these records are the client's
LOG = logging.getLogger('kessler_kos_driver.client')


class KosNotifications:
    """Notification and response dispatch of :class:`~.client.KosClient`."""

    def __init__(self, state: KosState) -> None:
        self.state = state
        self.on_playback: Callable[[PlaybackStatus], None] | None = None
        self.on_error: Callable[[ErrorEvent], None] | None = None
        self.on_motor_update: Callable[[], None] | None = None
        self.on_aux_inputs: Callable[[int], None] | None = None

    def dispatch(self, message: Message) -> None:
        """One message the session read (reader thread): into the state, then the
        adapter's callback, outside the state lock."""
        now = time.time()
        state = self.state
        callback: Callable[[], None] | None = None
        with state.cond:
            if isinstance(message, MotorInfo):
                self._apply_motor_info(message.motors, now)
                state.cond.notify_all()
                callback = self.on_motor_update
            elif isinstance(message, PlaybackStatus):
                self._apply_playback(message, now)
                state.completed(PLAYBACK_KEY)
                on_playback = self.on_playback
                if on_playback is not None:
                    callback = lambda: on_playback(message)  # noqa: E731
            elif isinstance(message, MotorPosition):
                motor = state.motors.get(message.motor_address)
                if motor is not None and math.isfinite(message.position):
                    # "sent after a motor has become idle" (spec, MotorPosition), and
                    # "after any attempt ... to change the motor position": a position
                    # report, not taken as a speed of 0 (an emulator may send it at once)
                    motor.report(message.position, now)
                state.completed(position_key(message.motor_address))
                callback = self.on_motor_update
            elif isinstance(message, MotorCalibrated):
                motor = state.motors.get(message.motor_address)
                if motor is not None:
                    motor.begin_position = message.begin_position
                    motor.end_position = message.end_position
                    if message.end_position == 0.0:
                        motor.position = 0.0
                    else:
                        motor.position = message.end_position
                state.completed(calibrated_key(message.motor_address))
            elif isinstance(message, MotorStatus):
                for entry in message.motors:
                    motor = state.motors.setdefault(entry.address, MotorState(entry.address))
                    motor.online = entry.online
                    motor.is_fiz = entry.motor_type == 1
                    motor.max_setup_speed = entry.max_setup_speed
                    motor.max_move_speed = entry.max_move_speed
                    motor.max_acceleration = entry.max_acceleration
                    LOG.warning('motor %d is now %s', entry.address,
                                'online' if entry.online else 'OFFLINE')
                callback = self.on_motor_update
            elif isinstance(message, ErrorStatus):
                event = ErrorEvent(message.error_code, message.motor_address,
                                   describe_error(message.error_code), now)
                state.errors.append(event)
                state.error_total += 1
                motor = state.motors.get(message.motor_address)
                if motor is not None:
                    motor.last_error = message.error_code
                state.completed(ERROR_KEY)
                LOG.warning('device error %d (%s), motor %d', event.code, event.description,
                            event.motor_address)
                on_error = self.on_error
                if on_error is not None:
                    callback = lambda: on_error(event)  # noqa: E731
            elif isinstance(message, AuxInputStatus):
                state.aux_inputs = status = message.status
                on_aux_inputs = self.on_aux_inputs
                if on_aux_inputs is not None:
                    callback = lambda: on_aux_inputs(status)  # noqa: E731
            elif isinstance(message, UnsupportedMessage):
                state.unsupported_replies += 1
                LOG.warning('device did not support a message: %s', message.offending.hex())
            elif isinstance(message, UnknownMessage):
                LOG.debug('ignoring unknown message id %#x', message.message_id)
            else:   # responses (DeviceInfo, DeviceGuid, ...): the session answers requests
                state.cond.notify_all()
        if callback:
            callback()

    def _apply_motor_info(self, entries: list[MotorInfoEntry], now: float) -> None:
        seen = set()
        for entry in entries:
            seen.add(entry.address)
            values = (entry.position, entry.begin_position, entry.end_position,
                      entry.max_setup_speed, entry.max_move_speed, entry.max_acceleration)
            if not all(math.isfinite(v) for v in values):
                LOG.warning('ignoring MotorInfo for motor %d with non-finite values',
                            entry.address)
                continue
            motor = self.state.motors.setdefault(entry.address, MotorState(entry.address))
            motor.report(entry.position, now)
            motor.begin_position = entry.begin_position
            motor.end_position = entry.end_position
            motor.max_setup_speed = entry.max_setup_speed
            motor.max_move_speed = entry.max_move_speed
            motor.max_acceleration = entry.max_acceleration
            motor.is_fiz = entry.is_fiz
            motor.online = True
        for address, motor in self.state.motors.items():
            if address not in seen:
                motor.online = False   # MotorInfo lists the connected motors only

    def _apply_playback(self, note: PlaybackStatus, now: float) -> None:
        pb = self.state.playback
        pb.status = note.status
        pb.elapsed = note.elapsed_time
        photos = note.photo_count
        pb.photo_count = round(photos) if math.isfinite(photos) and photos >= 0 else 0
        pb.positions = dict(note.positions)
        pb.history.append(note.status)
        if note.status == PlaybackState.SETUP_COMPLETED:
            pb.set_up = True
        if note.status == PlaybackState.FULL_STOP:
            pb.loaded = pb.set_up = False    # the move must be sent again
        for address, position in note.positions.items():
            motor = self.state.motors.get(address)
            if motor is not None and math.isfinite(position):
                motor.report(position, now)
