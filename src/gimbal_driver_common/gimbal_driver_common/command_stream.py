"""Gaps in the joint_command stream as this node took it, told apart from a publisher that
paused (no ROS).

A jog stops when no joint_command arrives within ``command_timeout`` (the dead-man
watchdog). When it fires while the client was publishing every cycle, the commands were
late on their way: in the middleware, or waiting for this node's executor. The user then
reads "jog expired" and sees a controller that never paused. So the node hands every
command's publisher timestamp and sequence number (rclpy's message info) to
:meth:`CommandStream.took`, which compares the gap between two commands it took with the
publisher's own interval over the same span: a gap longer than the dead-man window over
which the publisher kept to a period under half of it is a *delivery gap*. It is logged
(at most once every few seconds, with the count in between) and counted for the
``joint_command`` diagnostics part. The subscription keeps the last command only (newest
wins), so the commands published in the gap were superseded before the node took them; the
sequence numbers say how many.

The publisher's interval is read from its own timestamps and the gap from this node's
clock, so the two clocks are never compared: the rule holds across machines.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from gimbal_driver_common.config import Logger

#: a delivery gap is logged at most once in this many seconds
LOG_PERIOD_S = 5.0
#: the log line's opening words (tests read a node's log for it)
GAP_TEXT = 'took no joint_command for'
#: the keys of the ``joint_command`` diagnostics part: a count, and seconds
GAPS_KEY = 'delivery gaps'
LONGEST_GAP_KEY = 'longest delivery gap s'


@dataclass(frozen=True)
class DeliveryGap:
    """Two commands taken ``seconds`` apart, published ``publisher_period`` apart on average
    with ``superseded`` published in between (None: the middleware gave no sequence)."""

    seconds: float
    publisher_period: float
    superseded: int | None

    def describe(self) -> str:
        lost = ('' if self.superseded is None
                else f', {self.superseded} published in between were superseded before it')
        return (f'{GAP_TEXT} {self.seconds:.2f} s while its publisher sent one every '
                f'{self.publisher_period * 1000:.0f} ms{lost}: the middleware or this '
                f"node's executor delivered late (a jog may expire for it)")


class CommandStream:
    """Thread-safe record of when commands were published and taken, and of the gaps."""

    def __init__(self, log: Logger, window: Callable[[], float],
                 clock: Callable[[], float] = time.monotonic,
                 period: float = LOG_PERIOD_S) -> None:
        """``window``: the dead-man timeout in s, read at every command (it is a runtime
        parameter)."""
        self.log = log
        self.window = window
        self.period = period
        self._clock = clock
        self._lock = threading.Lock()
        self._last: tuple[float, int, int | None] | None = None  # taken at, published, seq
        self.gaps = 0
        self.longest: DeliveryGap | None = None
        self._logged_at = -math.inf
        self._unlogged = 0

    def took(self, published_ns: int, sequence: int | None) -> DeliveryGap | None:
        """One command taken now, published at ``published_ns`` (the publisher's clock) with
        the publisher's ``sequence`` number; returns the delivery gap it ended, if any."""
        now = self._clock()
        with self._lock:
            last, self._last = self._last, (now, published_ns, sequence)
            gap = self._judge(last, now, published_ns, sequence)
            if gap is None:
                return None
            self.gaps += 1
            if self.longest is None or gap.seconds > self.longest.seconds:
                self.longest = gap
            if now - self._logged_at < self.period:
                self._unlogged += 1
                return gap
            self._logged_at, unlogged, self._unlogged = now, self._unlogged, 0
        more = f' ({unlogged} more since the last such line)' if unlogged else ''
        self.log.warning(gap.describe() + more)
        return gap

    def _judge(self, last: tuple[float, int, int | None] | None, now: float,
               published_ns: int, sequence: int | None) -> DeliveryGap | None:
        if last is None:
            return None
        taken_at, last_published, last_sequence = last
        seconds, window = now - taken_at, self.window()
        if seconds <= window or published_ns <= last_published:
            return None  # on time, or another publisher (clocks not comparable)
        superseded = None
        intervals = 1
        if sequence is not None and last_sequence is not None:
            if sequence <= last_sequence:
                return None  # a new publisher (its sequence starts again)
            superseded = sequence - last_sequence - 1
            intervals = superseded + 1
        publisher_period = (published_ns - last_published) / 1e9 / intervals
        if publisher_period >= window / 2:
            return None  # the publisher itself paused: the watchdog was right
        return DeliveryGap(seconds, publisher_period, superseded)

    def values(self) -> list[tuple[str, str]]:
        """For the ``joint_command`` diagnostics part."""
        with self._lock:
            gaps, longest = self.gaps, self.longest
        return [(GAPS_KEY, str(gaps)),
                (LONGEST_GAP_KEY, f'{longest.seconds:.3f}' if longest else '0')]
