"""The kOS client's notification handling (no ROS): every message the session reads is
dispatched here, on the reader thread, into the client's state (motors, playback, errors,
aux inputs), waking the waiters and calling the adapter's callbacks.

A mixin of :class:`~.client.KosClient`, kept apart so the session (connection, messaging,
reader tick) reads in one sitting; the client provides the state it updates (``motors``,
``playback``, ``errors``, ``_seq``, ``_cond``) and the ``on_*`` callbacks.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable

from .client_types import ErrorEvent, MotorState, PlaybackInfo
from .protocol import (
    AuxInputStatus,
    ErrorStatus,
    Message,
    MessageId,
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

#: the client's logger: these records are the client's
LOG = logging.getLogger('kessler_kos_driver.client')


class KosNotifications:
    """Notification and response dispatch of :class:`~.client.KosClient` (a mixin)."""

    motors: dict[int, MotorState]
    playback: PlaybackInfo
    errors: deque[ErrorEvent]
    error_total: int
    unsupported_replies: int
    aux_inputs: int
    on_playback: Callable[[PlaybackStatus], None] | None
    on_error: Callable[[ErrorEvent], None] | None
    on_motor_update: Callable[[], None] | None
    on_aux_inputs: Callable[[int], None] | None
    _seq: dict[int, int]
    _cond: threading.Condition

    # --------------------------------------------------------------- notifications
    def _completed(self, key: int) -> None:
        self._seq[key] = self._seq.get(key, 0) + 1
        self._cond.notify_all()

    def _dispatch(self, message: Message) -> None:
        now = time.time()
        callback = None
        with self._cond:
            if isinstance(message, MotorInfo):
                self._apply_motor_info(message.motors, now)
                self._cond.notify_all()
                callback = self.on_motor_update
            elif isinstance(message, PlaybackStatus):
                self._apply_playback(message, now)
                self._completed(-MessageId.NOTIFICATION)
                callback = self.on_playback and (lambda: self.on_playback(message))
            elif isinstance(message, MotorPosition):
                motor = self.motors.get(message.motor_address)
                if motor is not None and math.isfinite(message.position):
                    motor.position, motor.velocity, motor.stamp = message.position, 0.0, now
                self._completed(-1000 - message.motor_address)
                callback = self.on_motor_update
            elif isinstance(message, MotorCalibrated):
                motor = self.motors.get(message.motor_address)
                if motor is not None:
                    motor.begin_position = message.begin_position
                    motor.end_position = message.end_position
                    if message.end_position == 0.0:
                        motor.position = 0.0
                    else:
                        motor.position = message.end_position
                self._completed(-2000 - message.motor_address)
            elif isinstance(message, MotorStatus):
                for entry in message.motors:
                    motor = self.motors.setdefault(entry.address, MotorState(entry.address))
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
                self.errors.append(event)
                self.error_total += 1
                motor = self.motors.get(message.motor_address)
                if motor is not None:
                    motor.last_error = message.error_code
                self._completed(-MessageId.NOTIFICATION - 3)
                LOG.warning('device error %d (%s), motor %d', event.code, event.description,
                            event.motor_address)
                callback = self.on_error and (lambda: self.on_error(event))
            elif isinstance(message, AuxInputStatus):
                self.aux_inputs = message.status
                status = message.status
                callback = self.on_aux_inputs and (lambda: self.on_aux_inputs(status))
            elif isinstance(message, UnsupportedMessage):
                self.unsupported_replies += 1
                LOG.warning('device did not support a message: %s', message.offending.hex())
            elif isinstance(message, UnknownMessage):
                LOG.debug('ignoring unknown message id %#x', message.message_id)
            else:   # responses (DeviceInfo, DeviceGuid, ...): the session answers requests
                self._cond.notify_all()
        if callback:
            callback()

    def _apply_motor_info(self, entries: list, now: float) -> None:
        seen = set()
        for entry in entries:
            seen.add(entry.address)
            values = (entry.position, entry.begin_position, entry.end_position,
                      entry.max_setup_speed, entry.max_move_speed, entry.max_acceleration)
            if not all(math.isfinite(v) for v in values):
                LOG.warning('ignoring MotorInfo for motor %d with non-finite values',
                            entry.address)
                continue
            motor = self.motors.setdefault(entry.address, MotorState(entry.address))
            if motor.stamp and now > motor.stamp:
                motor.velocity = (entry.position - motor.position) / (now - motor.stamp)
            motor.position = entry.position
            motor.begin_position = entry.begin_position
            motor.end_position = entry.end_position
            motor.max_setup_speed = entry.max_setup_speed
            motor.max_move_speed = entry.max_move_speed
            motor.max_acceleration = entry.max_acceleration
            motor.is_fiz = entry.is_fiz
            motor.online = True
            motor.stamp = now
        for address, motor in self.motors.items():
            if address not in seen:
                motor.online = False   # MotorInfo lists the connected motors only

    def _apply_playback(self, note: PlaybackStatus, now: float) -> None:
        pb = self.playback
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
            motor = self.motors.get(address)
            if motor is not None and math.isfinite(position):
                motor.position, motor.stamp = position, now
