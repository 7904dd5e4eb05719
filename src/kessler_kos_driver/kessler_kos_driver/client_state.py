"""What a kOS session knows of its device (no ROS): the motors, the playback, the errors the
device reported and the aux inputs, under one lock. The notifications part
(:class:`~.client_notifications.KosNotifications`) writes it on the reader thread; the
client, its commands (:class:`~.client_commands.KosCommands`) and the adapter read it and
wait on it. One object handed to each, so no part reads another's private state.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable

from .client_types import CommandRejected, ErrorEvent, MotorState, PlaybackInfo
from .protocol import PLAYBACK_RUNNING_STATES

#: keys of :meth:`KosState.count`: the notifications counted by kind
PLAYBACK_KEY, ERROR_KEY = -1, -2


def calibrated_key(address: int) -> int:
    """The count of MotorCalibrated notifications for one motor."""
    return -2000 - address


def position_key(address: int) -> int:
    """The count of MotorPosition notifications for one motor."""
    return -1000 - address


class KosState:
    """The device as the session last heard it; ``cond`` wakes waiters on each change."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.cond = threading.Condition(self.lock)
        self.motors: dict[int, MotorState] = {}
        self.playback = PlaybackInfo()
        self.errors: deque[ErrorEvent] = deque(maxlen=50)
        self.error_total = 0           # ErrorStatus notifications received so far
        self.aux_inputs = 0            # AuxInputStatus bits (DeviceInfo, then notifications)
        self.unsupported_replies = 0
        self._counts: dict[int, int] = {}   # notifications counted by kind (the keys above)

    @property
    def playback_running(self) -> bool:
        """True while the device executes a move (it then owns the motors)."""
        return self.playback.status in PLAYBACK_RUNNING_STATES

    def completed(self, key: int) -> None:
        """One more notification of this kind; waiters wake (call under ``cond``)."""
        self._counts[key] = self._counts.get(key, 0) + 1
        self.cond.notify_all()

    def count(self, key: int) -> int:
        with self.lock:
            return self._counts.get(key, 0)

    def reset_counts(self) -> None:
        """A new connection: the counts start again."""
        with self.lock:
            self._counts.clear()

    def wake(self) -> None:
        """Wake every waiter (a reply arrived, the link closed)."""
        with self.cond:
            self.cond.notify_all()

    def wait_for(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Wait until predicate() (evaluated under the state lock) holds."""
        deadline = time.monotonic() + timeout
        with self.cond:
            while not predicate():
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self.cond.wait(min(remaining, 0.1))
        return True

    def errors_since(self, marker: int) -> list[ErrorEvent]:
        """ErrorStatus events received after `marker` (a previous error_total)."""
        with self.lock:
            count = min(self.error_total - marker, len(self.errors))
            return list(self.errors)[len(self.errors) - count:] if count > 0 else []

    def motor(self, address: int) -> MotorState:
        """A connected, online motor, else :class:`CommandRejected` naming it."""
        motor = self.motors.get(address)
        if motor is None:
            known = ', '.join(str(a) for a in sorted(self.motors)) or 'none'
            raise CommandRejected(f'motor {address} is not connected (connected: {known})')
        if not motor.online:
            raise CommandRejected(f'motor {address} is offline')
        return motor
