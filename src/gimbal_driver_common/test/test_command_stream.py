"""CommandStream: a gap in the commands the node took is a delivery gap only when the
publisher kept publishing through it (its own timestamps and sequence numbers say so)."""

from __future__ import annotations

import pytest

from gimbal_driver_common.command_stream import GAP_TEXT, LOG_PERIOD_S, CommandStream

WINDOW = 0.5
MS = 1_000_000  # ns


class RecordingLog:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, msg: str) -> None:
        raise AssertionError(msg)

    def warning(self, msg: str) -> None:
        self.lines.append(msg)

    def error(self, msg: str) -> None:
        raise AssertionError(msg)


class Stream:
    """A publisher at ``period_ms`` and a node that takes what it is handed, on one fake
    clock (the publisher's clock runs 1000 s off the node's: they are never compared)."""

    def __init__(self, period_ms: int = 10, window: float = WINDOW) -> None:
        self.now, self.window = 50.0, window
        self.published_ns, self.sequence, self.period_ms = 1_000 * 1_000_000_000, 0, period_ms
        self.log = RecordingLog()
        self.stream = CommandStream(self.log, lambda: self.window, clock=lambda: self.now)

    def publish(self, count: int = 1) -> None:
        """``count`` commands go out; only the newest is kept (keep-last 1)."""
        self.published_ns += count * self.period_ms * MS
        self.sequence += count

    def take(self, after_s: float, sequence: bool = True):
        self.now += after_s
        return self.stream.took(self.published_ns, self.sequence if sequence else None)


def started(period_ms: int = 10, sequence: bool = True) -> Stream:
    """A stream whose first command the node has taken (nothing to compare before it)."""
    s = Stream(period_ms)
    s.publish()
    assert s.take(0.010, sequence) is None
    return s


def test_a_steady_stream_taken_on_time_has_no_gap() -> None:
    s = Stream()
    for _ in range(100):
        s.publish()
        assert s.take(0.010) is None
    assert s.log.lines == []
    assert s.stream.values() == [('delivery gaps', '0'), ('longest delivery gap s', '0')]


def test_commands_superseded_while_the_node_took_none_are_a_delivery_gap() -> None:
    s = started()
    s.publish(61)  # 60 of them overwritten before the node took the newest
    gap = s.take(0.62)
    assert gap is not None
    assert (gap.seconds, gap.superseded) == (pytest.approx(0.62), 60)
    assert gap.publisher_period == pytest.approx(0.010)
    [line] = s.log.lines
    assert line.startswith(f'{GAP_TEXT} 0.62 s while its publisher sent one every 10 ms, 60 ')
    assert s.stream.values() == [('delivery gaps', '1'), ('longest delivery gap s', '0.620')]


def test_a_publisher_that_paused_is_no_delivery_gap() -> None:
    """The dead-man stop was the client's doing: its own timestamps show the pause."""
    s = started(period_ms=700)
    s.publish()  # 0.7 s later by its clock, the next in sequence
    assert s.take(0.70) is None
    assert s.log.lines == []


def test_a_pause_of_several_commands_spaced_near_the_window_is_no_delivery_gap() -> None:
    """Superseded commands, but published 250 ms apart (half the window): a client too slow
    for its dead-man timeout, not a late delivery."""
    s = started(period_ms=250)
    s.publish(3)
    assert s.take(0.75) is None


def test_a_message_held_up_on_its_way_is_a_delivery_gap_without_superseded_ones() -> None:
    s = started()
    s.publish()  # published 10 ms after the last, taken 0.6 s after it
    gap = s.take(0.60)
    assert gap is not None and gap.superseded == 0


def test_no_sequence_numbers_judges_by_timestamps_alone() -> None:
    """Without them the span is one interval, an upper bound: a long one reads as a pause
    (no false alarm), a short one as a gap."""
    s = started(sequence=False)
    s.publish(61)
    assert s.take(0.62, sequence=False) is None
    s.publish(2)
    gap = s.take(0.62, sequence=False)
    assert gap is not None and gap.superseded is None
    assert gap.publisher_period == pytest.approx(0.020)
    assert 'superseded' not in s.log.lines[0]


def test_a_new_publisher_starts_a_new_stream() -> None:
    """Its sequence starts again, or its clock is behind: nothing is compared across."""
    s = Stream()
    s.publish(100)
    s.take(0.010)
    s.sequence = 1
    s.publish()
    assert s.take(0.62) is None
    s.published_ns -= 10_000 * MS
    s.publish()
    assert s.take(0.62) is None


def test_the_window_is_read_at_every_command() -> None:
    s = started()
    s.window = 1.0  # command_timeout raised at runtime
    s.publish(61)
    assert s.take(0.62) is None


def test_gaps_are_counted_every_time_and_logged_once_per_period() -> None:
    s = started()
    for _ in range(3):
        s.publish(61)
        assert s.take(0.62) is not None
    assert len(s.log.lines) == 1
    s.published_ns += int(LOG_PERIOD_S * 1e9)  # the publisher paused too: no gap
    s.publish()
    assert s.take(LOG_PERIOD_S) is None
    s.publish(81)
    assert s.take(0.81) is not None
    assert len(s.log.lines) == 2
    assert s.log.lines[1].endswith('(2 more since the last such line)')
    assert s.stream.values() == [('delivery gaps', '4'), ('longest delivery gap s', '0.810')]
