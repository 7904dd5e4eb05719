"""Refused joint_commands: counted by reason, and logged at most once per reason every few
seconds (no ROS).

A joint_command has no answer, so the node says in its log why it did not carry one out.
A client that streams (ros2_control's topic interface writes every control cycle, 100 Hz)
and is refused for a while would otherwise write one line per message: 301 WARN lines in
3 s were measured. So each distinct reason (:attr:`GimbalError.reason`: what went wrong
without the values, e.g. ``pan: position outside the limits``) is logged when it first
occurs, then at most once every :data:`LOG_PERIOD_S` seconds, with the number of
occurrences in between; :class:`CommandRejections` counts every one of them, by kind and
reason, for the ``joint_command`` diagnostics part (level OK: a refused command is the
client's fault or the device's state, and the connection and device parts report the
device).

Every refusal path of ``joint_command`` goes through :meth:`CommandRejections.record`:
validation (*rejected*: the message itself is wrong), an inactive or disconnected node, an
axis the device cannot move and a send the device failed (*refused*).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

from gimbal_driver_common.config import Logger
from gimbal_driver_common.diagnostics import Level, StatusPart
from gimbal_driver_common.errors import GimbalError, InvalidRequest

#: a reason is logged at most once in this many seconds ("every few seconds")
LOG_PERIOD_S = 5.0
REJECTED = 'rejected'
REFUSED = 'refused'


class CommandRejections:
    """Thread-safe counts of refused joint_commands and the throttle of their log lines."""

    def __init__(self, log: Logger, period: float = LOG_PERIOD_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.log = log
        self.period = period
        self._clock = clock
        self._lock = threading.Lock()
        self._counts: dict[tuple[str, str], int] = {}
        self._logged_at: dict[tuple[str, str], float] = {}
        self._unlogged: dict[tuple[str, str], int] = {}

    def record(self, error: GimbalError, sent: bool = False) -> None:
        """One joint_command not carried out. ``sent`` False: validation or a refusal, so
        nothing went to the device; True: the device failed the send."""
        if sent:
            key = (REFUSED, f'failed on the device: {error.reason}')
            text = f'joint_command failed on the device: {error}'
        elif isinstance(error, InvalidRequest):
            key = (REJECTED, error.reason)
            text = f'joint_command rejected, nothing sent: {error}'
        else:
            key = (REFUSED, error.reason)
            text = f'joint_command refused, nothing sent: {error}'
        now = self._clock()
        with self._lock:
            self._counts[key] = self._counts.get(key, 0) + 1
            if now - self._logged_at.get(key, -math.inf) < self.period:
                self._unlogged[key] = self._unlogged.get(key, 0) + 1
                return
            self._logged_at[key] = now
            unlogged = self._unlogged.pop(key, 0)
        if unlogged:
            text += f' ({unlogged} more for this reason since the last such line)'
        # one call site per severity: rclpy's logger refuses a call site whose severity
        # changes between calls ("Logger severity cannot be changed between calls")
        if sent:
            self.log.error(text)
        else:
            self.log.warning(text)

    def counts(self) -> dict[str, dict[str, int]]:
        """kind (``rejected``/``refused``) -> reason -> how many so far."""
        with self._lock:
            counts = dict(self._counts)
        result: dict[str, dict[str, int]] = {REJECTED: {}, REFUSED: {}}
        for (kind, reason), count in sorted(counts.items()):
            result[kind][reason] = count
        return result

    def status_part(self, extra: list[tuple[str, str]] | None = None) -> StatusPart:
        """The ``joint_command`` diagnostics part: totals, one value per reason, then
        ``extra`` (the node's delivery gaps: :mod:`~gimbal_driver_common.command_stream`)."""
        counts = self.counts()
        totals = {kind: sum(by_reason.values()) for kind, by_reason in counts.items()}
        values = [(kind, str(total)) for kind, total in totals.items()]
        for kind, by_reason in counts.items():
            values += [(f'{kind}: {reason}', str(count)) for reason, count in by_reason.items()]
        values += extra or []
        message = (f'{totals[REJECTED]} rejected, {totals[REFUSED]} refused'
                   if any(totals.values()) else 'none rejected or refused')
        return StatusPart('joint_command', Level.OK, message, values)
