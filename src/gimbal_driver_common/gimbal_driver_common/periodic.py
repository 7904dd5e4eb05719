"""Periodic jobs on one plain thread instead of executor timers.

Every wake-up of an rclpy executor rebuilds its wait set in Python
and competes for the GIL with the device thread; measured as CPU and
joint_states latency. So the jog watchdog, diagnostics and ~/status run here.

Jobs run on a common grid (multiples of their period on the monotonic clock, after
the first run), so jobs whose periods divide each other run in one wake-up: a thread
wakes as often as its fastest job, not once per job. A wake-up costs about as much CPU
as the quick job it runs (bench/README.md, "Fewer wake-ups").
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

#: a job's period in s, or a function giving it (read at each run: a run-time parameter)
Period = float | Callable[[], float]


def period_of(period: Period) -> float:
    return period() if callable(period) else period


def next_on_grid(period: float, after: float) -> float:
    """The first multiple of ``period`` later than ``after`` (monotonic s)."""
    return (math.floor(after / period) + 1.0) * period if period > 0 else after


class Periodic:
    """Runs callbacks every ``period`` s; callbacks must be thread-safe and quick."""

    def __init__(
        self, on_error: Callable[[str], object] = print, name: str = 'housekeeping'
    ) -> None:
        self._on_error = on_error
        self._name = name
        self._jobs: list[list] = []  # [period, next due, callback]
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stopped = threading.Event()
        self._thread: threading.Thread | None = None
        #: times the thread woke and ran jobs (tests, benchmarks)
        self.wakeups = 0

    def add(self, period: Period, callback: Callable[[], object]) -> None:
        """Run ``callback`` every ``period`` s, first ``period`` s from now."""
        with self._lock:
            self._jobs.append([period, time.monotonic() + period_of(period), callback])
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
                self._thread.start()
        self._wake.set()

    def set_period(self, callback: Callable[[], object], period: Period) -> None:
        """Change a job's period; it next runs ``period`` s from now."""
        with self._lock:
            for job in self._jobs:
                if job[2] == callback:
                    job[0], job[1] = period, time.monotonic() + period_of(period)
        self._wake.set()

    def trigger(self, callback: Callable[[], object]) -> None:
        """Run a job as soon as possible (then every period again), e.g. a topic that
        should publish at once when it is switched on rather than one period later."""
        with self._lock:
            for job in self._jobs:
                if job[2] == callback:
                    job[1] = time.monotonic()
        self._wake.set()

    def remove(self, callback: Callable[[], object]) -> None:
        with self._lock:
            self._jobs = [job for job in self._jobs if job[2] != callback]

    def stop(self) -> None:
        self._stopped.set()
        self._wake.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)

    def _run(self) -> None:
        while not self._stopped.is_set():
            now = time.monotonic()
            with self._lock:
                due = [job for job in self._jobs if job[1] <= now]
                for job in due:
                    job[1] = next_on_grid(period_of(job[0]), max(job[1], now))
                next_due = min((job[1] for job in self._jobs), default=now + 1.0)
                self.wakeups += bool(due)
            for _, _, callback in due:
                if self._stopped.is_set():
                    return
                try:
                    callback()
                except Exception as exc:  # noqa: BLE001 - one failing job must not stop others
                    self._on_error(f'periodic {getattr(callback, "__name__", callback)}: {exc!r}')
            if self._wake.wait(max(0.0, next_due - time.monotonic())):
                self._wake.clear()


class PacedJob:
    """A :class:`Periodic` job that runs often only while it has work.

    An idle driver's housekeeping thread woke 20 times a second to find no jog to watch
    and no stop to confirm. ``busy`` says whether there is work. Whoever starts work calls
    :meth:`pace` (the fast period from then on) and the run that finds none left switches
    back to ``idle``; both decide under one lock from ``busy`` itself, so work started
    while a run switches to slow is seen by one of them and never waits the slow period.
    """

    def __init__(self, periodic: Periodic, callback: Callable[[], object],
                 busy: Callable[[], bool], fast: Callable[[], float], idle: float) -> None:
        """``fast`` is read at each switch (a parameter may change it); <= 0: always idle."""
        self.periodic = periodic
        self._callback = callback
        self._busy = busy
        self._fast_period = fast
        self.idle = idle
        self._lock = threading.Lock()
        self._fast = False
        periodic.add(self.period(), self.run)

    def period(self) -> float:
        fast = self._fast_period()
        return fast if self._fast and fast > 0 else self.idle

    def run(self) -> None:
        """The job as the housekeeping thread runs it: the work, then the pace."""
        self._callback()
        self.pace()

    def pace(self) -> None:
        """Fast while ``busy``, idle otherwise; the period changes only on a switch."""
        with self._lock:
            fast = bool(self._busy())
            if fast != self._fast:
                self._fast = fast
                self.periodic.set_period(self.run, self.period())

    def repace(self) -> None:
        """The fast period itself changed: take it now."""
        with self._lock:
            self.periodic.set_period(self.run, self.period())

    def remove(self) -> None:
        self.periodic.remove(self.run)
