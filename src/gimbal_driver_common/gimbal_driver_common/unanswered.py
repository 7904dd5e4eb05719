"""Requests a device leaves unanswered, and when to ask them again (no ROS); and the reads
at connect a node can work without (:class:`ConnectReads`).

An optional subsystem that is not fitted, or firmware that drops what it cannot serve,
leaves one kind of request unanswered while the device answers everything else. Asking
it again at once, every time, costs the link a timeout per ask. So each unanswered
request is counted by name, and asked again only after a back-off that doubles with every
timeout in a row (``first`` s, then 2x, up to ``longest``); an answer clears it. The
counts go to ``/diagnostics`` (a WARN naming the request and how often it went
unanswered); one unanswered kind of request never makes a device that answers the rest
"silent": that is judged on the requests the driver cannot work without.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from gimbal_driver_common.errors import DeviceTimeout

__all__ = ['BackingOff', 'ConnectReads', 'Unanswered', 'UnansweredRequest',
           'backing_off_message']

T = TypeVar('T')


class BackingOff(DeviceTimeout):
    """Not sent: the request went unanswered and its back-off has not run out yet."""

    def __init__(self, name: str, count: int, retry_in: float) -> None:
        super().__init__(backing_off_message(name, count, retry_in))
        self.name, self.count, self.retry_in = name, count, retry_in


def backing_off_message(name: str, count: int, retry_in: float) -> str:
    """What a request not sent for its back-off says (one wording for every client)."""
    return f'{name}: unanswered {count} time(s) in a row; asked again in {retry_in:.1f} s'


@dataclass(frozen=True)
class UnansweredRequest:
    """One request's record: timeouts in a row, in all, and when it may be asked again."""

    name: str
    in_a_row: int
    total: int
    retry_at: float


class Unanswered:
    """Thread-safe book of unanswered requests with a doubling back-off per name."""

    def __init__(self, first: float = 1.0, longest: float = 30.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if first <= 0 or longest < first:
            raise ValueError(f'back-off {first}..{longest} s: need 0 < first <= longest')
        self.first, self.longest = first, longest
        self._clock = clock
        self._lock = threading.Lock()
        self._records: dict[str, UnansweredRequest] = {}

    def waiting(self, name: str) -> tuple[UnansweredRequest, float] | None:
        """``name``'s record and the seconds left of its back-off, or None: ask it now."""
        with self._lock:
            record = self._records.get(name)
        if record is None or record.in_a_row == 0:
            return None
        left = record.retry_at - self._clock()
        return (record, left) if left > 0 else None

    def check(self, name: str) -> None:
        """Raise :class:`BackingOff` (nothing to send) while ``name`` waits out its back-off."""
        waiting = self.waiting(name)
        if waiting is not None:
            raise BackingOff(name, waiting[0].in_a_row, waiting[1])

    def timed_out(self, name: str) -> UnansweredRequest:
        """One more timeout of ``name``: its next ask waits twice as long as the last."""
        with self._lock:
            old = self._records.get(name)
            in_a_row = (old.in_a_row if old else 0) + 1
            total = (old.total if old else 0) + 1
            backoff = min(self.first * 2 ** (in_a_row - 1), self.longest)
            record = UnansweredRequest(name, in_a_row, total, self._clock() + backoff)
            self._records[name] = record
            return record

    def answered(self, name: str) -> None:
        """``name`` got its answer: asked as usual again (its total stays on record)."""
        with self._lock:
            old = self._records.get(name)
            if old is not None and old.in_a_row:
                self._records[name] = UnansweredRequest(name, 0, old.total, 0.0)

    def clear(self) -> None:
        """A new connection (maybe another device): nothing on record."""
        with self._lock:
            self._records.clear()

    def silent(self) -> list[UnansweredRequest]:
        """The requests unanswered at their last ask, by name."""
        with self._lock:
            return sorted((r for r in self._records.values() if r.in_a_row),
                          key=lambda r: r.name)

    def diagnostics(self) -> list[tuple[str, str]]:
        """Key/values for a diagnostics status: ``unanswered.<request>``."""
        now = self._clock()
        return [(f'unanswered.{r.name}',
                 f'{r.in_a_row} time(s) in a row ({r.total} in all); asked again in '
                 f'{max(0.0, r.retry_at - now):.1f} s') for r in self.silent()]


class ConnectReads:
    """Reads at connect the node can work without (an identity detail, a read-back): one
    left unanswered is a WARN, a diagnostics key and a note in the status message, and
    connecting goes on. Only what the node cannot work without is required; its failure
    names it (the driver's own code, not this). Thread-safe; cleared at every connect."""

    def __init__(self, log: Callable[[str], object]) -> None:
        self._log = log
        self._lock = threading.Lock()
        self._missing: dict[str, str] = {}

    def clear(self) -> None:
        with self._lock:
            self._missing.clear()

    def read(self, name: str, read: Callable[[], T],
             errors: tuple[type[BaseException], ...] = (DeviceTimeout,)) -> T | None:
        """``read()``, or None (logged once, named in diagnostics) when it fails with one
        of ``errors``: no answer, by default."""
        try:
            value = read()
        except errors as exc:
            self.missed(name, str(exc))
            return None
        with self._lock:
            self._missing.pop(name, None)
        return value

    def missed(self, name: str, why: str) -> None:
        """``name`` went unanswered at connect (for a read whose failure needs a check of
        the driver's own first, such as the turret's IDS while its broadcasts arrive)."""
        with self._lock:
            self._missing[name] = why
        self._log(f'{name} unanswered at connect, connecting without it: {why}')

    def __contains__(self, name: object) -> bool:
        with self._lock:
            return name in self._missing

    def __len__(self) -> int:
        with self._lock:
            return len(self._missing)

    def diagnostics(self) -> list[tuple[str, str]]:
        """Key/values for the device's status: ``unanswered.<read>`` and why."""
        with self._lock:
            return [(f'unanswered.{name}', why) for name, why in self._missing.items()]

    def summary(self) -> str:
        """``unanswered at connect: A, B`` for the status message ('' when none)."""
        with self._lock:
            names = list(self._missing)
        return f'unanswered at connect: {", ".join(names)}' if names else ''
