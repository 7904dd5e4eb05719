"""Decode device status/error registers into named flags with severities.

Each driver describes its registers as tables of :class:`RegisterFlag`; the
decoded flags become DiagnosticStatus key/values and the worst severity
becomes the status level (the ROS side lives in ``gimbal_driver_common.ros``).
Levels use DiagnosticStatus numbering so no ROS import is needed here.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from enum import IntEnum


class Level(IntEnum):
    """diagnostic_msgs/DiagnosticStatus levels."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


@dataclass(frozen=True)
class RegisterFlag:
    """One bit (or masked field equal to ``value``) of a device register."""

    bit: int
    name: str
    level: Level = Level.OK
    description: str = ''
    active_low: bool = False  # set when the flag means "bit is 0" (e.g. "axis not powered")

    @property
    def mask(self) -> int:
        return 1 << self.bit


@dataclass(frozen=True)
class ActiveFlag:
    register: str
    flag: RegisterFlag

    @property
    def key(self) -> str:
        return f'{self.register}.{self.flag.name}'


def decode_register(
    value: int, flags: Sequence[RegisterFlag], register: str = ''
) -> list[ActiveFlag]:
    """Return the flags that are set in ``value`` (bit order)."""
    active = []
    for flag in flags:
        is_set = bool(value & flag.mask)
        if is_set != flag.active_low:
            active.append(ActiveFlag(register, flag))
    return active


def worst_level(levels: Iterable[int]) -> Level:
    """Highest severity; STALE outranks nothing but is kept when it is all there is."""
    worst = Level.OK
    for level in levels:
        if level == Level.STALE:
            if worst == Level.OK:
                worst = Level.STALE
            continue
        if worst == Level.STALE or level > worst:
            worst = Level(level)
    return worst


def summarize(active: Sequence[ActiveFlag], ok_message: str = 'OK') -> tuple[Level, str]:
    """Level and one-line message for a set of active flags (worst first)."""
    problems = [a for a in active if a.flag.level > Level.OK]
    if not problems:
        return Level.OK, ok_message
    problems.sort(key=lambda a: -int(a.flag.level))
    level = worst_level(a.flag.level for a in problems)
    names = ', '.join(a.flag.description or a.flag.name for a in problems[:3])
    more = f' (+{len(problems) - 3} more)' if len(problems) > 3 else ''
    return level, names + more


def flags_to_key_values(active: Sequence[ActiveFlag]) -> list[tuple[str, str]]:
    """Key/value pairs for DiagnosticStatus.values: one per active flag."""
    return [(a.key, a.flag.description or 'set') for a in active]


class FrequencyMonitor:
    """Measures an event rate over a sliding window (like diagnostic_updater's FrequencyStatus).

    ``tick`` on every published message; ``status`` compares the measured rate
    with the expected one within ``tolerance`` (0.1 = +-10 %). Thread-safe (ticks come from
    the device thread, samples from the diagnostics timer, rate changes from parameters),
    as FrequencyStatus keeps its statistics under a lock.
    """

    def __init__(self, expected_hz: float, tolerance: float = 0.1, window: int = 5) -> None:
        self.expected_hz = expected_hz
        self.tolerance = tolerance
        self._window = window
        self._counts: list[tuple[float, int]] = []
        self._count = 0
        self._lock = threading.Lock()
        self._publish_rate: float | None = None

    def tick(self) -> None:
        with self._lock:
            self._count += 1

    def sample(self, now: float, live: bool = True) -> None:
        """Call periodically (each diagnostics period) to close a window slot.

        ``live`` False (not publishing: inactive, or the link down): the window starts
        again. A window that spans such a pause reads as a low rate for up to ``window``
        periods after publishing resumes: a healthy device read WARN "frequency too low"
        for a few seconds after activation (seen in a full test run).
        """
        with self._lock:
            if not live:
                self._counts.clear()
                return
            self._counts.append((now, self._count))
            if len(self._counts) > self._window:
                self._counts.pop(0)

    def restart(self) -> None:
        """Start the window again at the newest sample, as diagnostic_updater's
        ``FrequencyStatus.clear()`` (diagnostic_updater/_update_functions.py, and
        update_functions.hpp) resets its history: the rate is then measured only over what
        was published after it. Here the window starts at the newest sample rather than at
        the call, so the first rate after a restart spans a whole period, never a few ms."""
        with self._lock:
            self._counts = self._counts[-1:]

    def follow_publish_rate(self, publish_rate: float) -> None:
        """The node's ``publish_rate`` now: when it changed since the last call, the window
        restarts (:meth:`restart`), so a window that is half old rate, half new does not read
        "too low" or "too high" for ``window`` periods. Call it after :meth:`sample` of the
        same period: that sample was taken after the change and starts the new window."""
        with self._lock:
            changed = self._publish_rate is not None and publish_rate != self._publish_rate
            self._publish_rate = publish_rate
        if changed:
            self.restart()

    @property
    def rate_hz(self) -> float:
        return self._measured()[0]

    def _measured(self) -> tuple[float, bool]:
        """(rate, whether the window has two samples yet), from one view of the window."""
        with self._lock:
            counts = list(self._counts)
        if len(counts) < 2:
            return 0.0, False
        (t0, c0), (t1, c1) = counts[0], counts[-1]
        return ((c1 - c0) / (t1 - t0) if t1 > t0 else 0.0), True

    def status(self) -> tuple[Level, str]:
        rate, measured = self._measured()
        if not measured:
            return Level.OK, 'measuring'
        low = self.expected_hz * (1.0 - self.tolerance)
        high = self.expected_hz * (1.0 + self.tolerance)
        if rate == 0.0:
            return Level.ERROR, 'no events'
        if rate < low:
            return Level.WARN, f'frequency too low ({rate:.1f} Hz, expected {self.expected_hz:g})'
        if rate > high:
            return Level.WARN, f'frequency too high ({rate:.1f} Hz, expected {self.expected_hz:g})'
        return Level.OK, f'{rate:.1f} Hz'


@dataclass
class StatusPart:
    """One DiagnosticStatus before naming: ``part`` becomes ``<node name>: <part>``."""

    part: str
    level: Level = Level.OK
    message: str = 'OK'
    values: list[tuple[str, str]] = field(default_factory=list)

    @classmethod
    def from_flags(
        cls,
        part: str,
        active: Iterable[ActiveFlag],
        extra_values: Iterable[tuple[str, str]] = (),
        ok_message: str = 'OK',
    ) -> StatusPart:
        """A status whose level and message come from decoded register flags."""
        active = list(active)
        level, message = summarize(active, ok_message)
        return cls(part, level, message, [*extra_values, *flags_to_key_values(active)])
