"""Message-code sequencing (ICD 4.1): detect lost, repeated and late NOD messages.

"For Normal Operation Data (NOD) the Message Code is incremented by one for each
message with a particular CAN identifier by the transmitting node. After reaching the
value of 255, the Message Code rolls over to zero."

Classification of a received code against the last accepted one (mod 256 distance d):
d == 1 in order; d == 0 repeated; 2 <= d <= `lost_window` lost (d - 1 missing);
d > `lost_window` (i.e. "behind" the last one) late: an old message arriving after
newer ones; it is reported and does not move the reference. The default window of 128
splits the ring in half, the usual choice for an 8-bit sequence number.

Two situations would otherwise make a receiver drop good data for a long time:
* the transmitter restarted (codes begin again at 0): `streak` late codes in a row
  re-anchor the sequence (RESTARTED) instead of counting ~128 frames as late;
* the transmitter does not increment the code at all (non-compliant, or a constant code
  such as the 0 in the ICD's command examples): `streak` repeats in a row mark the key
  UNSEQUENCED, after which its messages are accepted without sequence checks until the
  code changes again.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass
from enum import Enum
from typing import Generic, TypeVar

#: what a tracker is keyed by (the client: (node-id, CAN id))
K = TypeVar("K", bound=Hashable)


class SequenceEvent(Enum):
    FIRST = "first"
    IN_ORDER = "in_order"
    LOST = "lost"
    REPEATED = "repeated"
    LATE = "late"
    RESTARTED = "restarted"
    UNSEQUENCED = "unsequenced"

    @property
    def accepted(self) -> bool:
        """Should the receiver use the value (False: duplicate or out of date)?"""
        return self not in (SequenceEvent.REPEATED, SequenceEvent.LATE)


@dataclass
class SequenceStats:
    """Counters for one identifier."""

    received: int = 0
    lost: int = 0
    repeated: int = 0
    late: int = 0
    restarts: int = 0
    last_code: int | None = None
    streak: int = 0  # consecutive repeated or late codes
    unsequenced: bool = False

    @property
    def anomalies(self) -> int:
        return self.lost + self.repeated + self.late


class MessageCodeTracker(Generic[K]):
    """Per-key (normally (node-id, CAN id)) message-code bookkeeping."""

    def __init__(self, lost_window: int = 128, streak: int = 3) -> None:
        if not 1 <= lost_window <= 255:
            raise ValueError("lost_window must be 1..255")
        self._lost_window = lost_window
        self._streak = streak
        self._stats: dict[K, SequenceStats] = {}

    def update(self, key: K, code: int) -> tuple[SequenceEvent, int]:
        """Account for one received code; returns (event, number of messages missed)."""
        if not 0 <= code <= 255:
            raise ValueError(f"message code {code} is not 0..255")
        stats = self._stats.setdefault(key, SequenceStats())
        stats.received += 1
        if stats.last_code is None:
            stats.last_code = code
            return SequenceEvent.FIRST, 0
        distance = (code - stats.last_code) % 256
        if stats.unsequenced:
            if distance == 0:
                return SequenceEvent.UNSEQUENCED, 0
            stats.unsequenced = False  # the code moves again: track it from here
            stats.last_code, stats.streak = code, 0
            return SequenceEvent.FIRST, 0
        if distance == 1:
            stats.last_code, stats.streak = code, 0
            return SequenceEvent.IN_ORDER, 0
        if distance == 0:
            stats.streak += 1
            if stats.streak >= self._streak:
                stats.unsequenced = True
                return SequenceEvent.UNSEQUENCED, 0
            stats.repeated += 1
            return SequenceEvent.REPEATED, 0
        if distance <= self._lost_window:
            stats.lost += distance - 1
            stats.last_code, stats.streak = code, 0
            return SequenceEvent.LOST, distance - 1
        stats.streak += 1
        if stats.streak >= self._streak:
            stats.restarts += 1
            stats.last_code, stats.streak = code, 0
            return SequenceEvent.RESTARTED, 0
        stats.late += 1
        return SequenceEvent.LATE, 0

    def reset(self, key: K | None = None) -> None:
        """Forget one key (e.g. after the node went silent) or all keys."""
        if key is None:
            self._stats.clear()
        else:
            self._stats.pop(key, None)

    def stats(self, key: K) -> SequenceStats:
        return self._stats.get(key, SequenceStats())

    def all_stats(self) -> dict[K, SequenceStats]:
        return dict(self._stats)


class MessageCodeCounter:
    """Transmit side: the next message code per CAN id, rolling over after 255."""

    def __init__(self) -> None:
        self._next: dict[int, int] = {}

    def next(self, can_id: int) -> int:
        code = self._next.get(can_id, 0)
        self._next[can_id] = (code + 1) % 256
        return code
