"""Dead-man watchdog for jog (velocity) commands.

A jog keeps an axis moving until told otherwise; if the commanding process
dies or the network stalls, the axis must stop by itself. Every jog feeds the
watchdog; :meth:`JogWatchdog.check` (called from a timer) returns the joints
whose jog expired so the driver can send them an explicit stop.
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
    ) -> None:
        self.timeout_s = timeout_s
        self._on_expire = on_expire
        self._clock = clock
        self._last_fed: dict[str, float] = {}
        self._lock = threading.Lock()

    @property
    def enabled(self) -> bool:
        """A timeout <= 0 disables the watchdog (jogs then run until stopped)."""
        return self.timeout_s > 0

    @property
    def jogging(self) -> list[str]:
        with self._lock:
            return sorted(self._last_fed)

    def feed(self, joint_names: Iterable[str]) -> None:
        """Record a fresh jog command for these joints."""
        now = self._clock()
        with self._lock:
            for name in joint_names:
                self._last_fed[name] = now

    def cancel(self, joint_names: Iterable[str] | None = None) -> None:
        """Forget joints (they got a position move or a stop); ``None`` forgets all."""
        with self._lock:
            if joint_names is None:
                self._last_fed.clear()
            else:
                for name in joint_names:
                    self._last_fed.pop(name, None)

    def check(self, now: float | None = None) -> list[str]:
        """Return (and forget) the joints whose jog expired; calls ``on_expire`` with them."""
        if not self.enabled:
            return []
        now = self._clock() if now is None else now
        with self._lock:
            expired = sorted(
                name for name, fed in self._last_fed.items() if now - fed >= self.timeout_s
            )
            for name in expired:
                del self._last_fed[name]
        if expired and self._on_expire is not None:
            self._on_expire(expired)
        return expired
