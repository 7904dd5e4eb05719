"""Dead-man watchdog for jog (velocity) commands.

A jog keeps an axis moving until told otherwise; if the commanding process
dies or the network stalls, the axis must stop by itself. Every jog feeds the
watchdog; :meth:`JogWatchdog.check` (called from a timer) returns the joints
whose jog expired so the driver can send them an explicit stop. An expired joint is kept
(:attr:`JogWatchdog.stopping`) until ``settled`` says its axis is at rest (the
controller's stop watch, which sends the stop again meanwhile): the watchdog forgets a
joint only then, or when a new jog or another command takes it over.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable


class JogWatchdog:
    """Tracks when each jogging joint was last commanded."""

    def __init__(
        self,
        timeout_s: float,
        on_expire: Callable[[list[str]], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
        settled: Callable[[str], bool] = lambda joint: True,
    ) -> None:
        self.timeout_s = timeout_s
        self._on_expire = on_expire
        self._clock = clock
        self._settled = settled
        self._last_fed: dict[str, float] = {}
        #: joints whose jog expired and whose axis is not confirmed at rest yet
        self._stopping: set[str] = set()
        self._lock = threading.Lock()

    @property
    def enabled(self) -> bool:
        """A timeout <= 0 disables the watchdog (jogs then run until stopped)."""
        return self.timeout_s > 0

    @property
    def jogging(self) -> list[str]:
        with self._lock:
            return sorted(self._last_fed)

    @property
    def stopping(self) -> list[str]:
        """Joints whose jog expired, stopped, and not yet confirmed at rest."""
        with self._lock:
            return sorted(self._stopping)

    def feed(self, joint_names: Iterable[str]) -> None:
        """Record a fresh jog command for these joints."""
        now = self._clock()
        with self._lock:
            for name in joint_names:
                self._last_fed[name] = now
                self._stopping.discard(name)

    def cancel(self, joint_names: Iterable[str] | None = None) -> None:
        """Forget joints (they got a position move or a stop); ``None`` forgets all."""
        with self._lock:
            if joint_names is None:
                self._last_fed.clear()
                self._stopping.clear()
            else:
                for name in joint_names:
                    self._last_fed.pop(name, None)
                    self._stopping.discard(name)

    def check(self, now: float | None = None) -> list[str]:
        """Return the joints whose jog expired (they move to :attr:`stopping`); calls
        ``on_expire`` with them. Forgets the stopping joints whose axis is at rest."""
        with self._lock:
            stopping = sorted(self._stopping)
        settled = {name for name in stopping if self._settled(name)}
        if not self.enabled:
            with self._lock:
                self._stopping -= settled
            return []
        now = self._clock() if now is None else now
        with self._lock:
            self._stopping -= settled
            expired = sorted(
                name for name, fed in self._last_fed.items() if now - fed >= self.timeout_s
            )
            for name in expired:
                del self._last_fed[name]
            self._stopping.update(expired)
        if expired and self._on_expire is not None:
            self._on_expire(expired)
        return expired
