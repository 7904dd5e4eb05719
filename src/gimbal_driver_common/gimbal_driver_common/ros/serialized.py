"""joint_states as the bytes the middleware sends: one serialized message, patched per sample.

``Publisher.publish(msg)`` converts the Python message into its C struct and serializes it
on every call. At 50 Hz, with the device thread asleep between samples, that conversion
was a third of the node's publishing cost on the bench machine. For a fixed set of names
(and effort count) a JointState's serialized form has the same length and layout each
time: only the stamp and the doubles change. So the middleware serializes it once
(``rclpy.serialization.serialize_message``, the rmw's own format), the offsets of the
stamp and of each double are found in those bytes, and each sample is written in place
(``struct.pack_into``); ``Publisher.publish`` takes ``bytes`` and sends them as they are.

The layout is found, not assumed: the template is serialized with sentinel values, each
must be found exactly once, and a message patched with test values must deserialize to
those values. Where any of it fails (another middleware's format, a big-endian host),
:meth:`JointStateLayout.build` returns None and the caller publishes the message itself.
"""

from __future__ import annotations

import math
import struct
from array import array
from collections.abc import Sequence

from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

#: what the template is serialized with, to find where the stamp and the values go
SENTINEL_SEC = 0x3A5B7C1D
SENTINEL_NANOSEC = 0x1D2C3B4A
STAMP = struct.Struct('<iI')


def sentinel(index: int) -> float:
    """A double whose 8 bytes occur nowhere else in a serialized JointState."""
    return -1.234567890123e-301 * (index + 3.25)


class JointStateLayout:
    """The serialized JointState of one shape (names, effort count), patched per sample."""

    def __init__(self, buffer: bytearray, stamp_at: int,
                 sequences: list[tuple[struct.Struct, int]]) -> None:
        self.buffer = buffer
        self.stamp_at = stamp_at
        #: (packer, offset) of position, velocity, effort (absent when it has no values)
        self.sequences = sequences

    @classmethod
    def build(cls, names: Sequence[str], effort_count: int) -> JointStateLayout | None:
        """The layout for ``names`` with ``effort_count`` efforts (0 or len(names)), or
        None where the serialized form is not the one this expects."""
        count = len(names)
        counts = [count, count, effort_count]
        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = SENTINEL_SEC, SENTINEL_NANOSEC
        msg.name = list(names)
        values = [sentinel(i) for i in range(sum(counts))]
        msg.position = array('d', values[:count])
        msg.velocity = array('d', values[count:2 * count])
        msg.effort = array('d', values[2 * count:])
        raw = serialize_message(msg)
        stamp_at = unique_offset(raw, STAMP.pack(SENTINEL_SEC, SENTINEL_NANOSEC))
        if stamp_at is None:
            return None
        sequences = []
        first = 0
        for length in counts:
            if length == 0:
                continue
            offsets = [unique_offset(raw, struct.pack('<d', values[first + i]))
                       for i in range(length)]
            if offsets[0] is None or offsets != [offsets[0] + 8 * i for i in range(length)]:
                return None
            sequences.append((struct.Struct(f'<{length}d'), offsets[0]))
            first += length
        layout = cls(bytearray(raw), stamp_at, sequences)
        return layout if layout.round_trips(list(names), counts) else None

    def write(self, stamp: float, *values: Sequence[float]) -> bytes:
        """The serialized message for ``stamp`` (s) and the values of each sequence
        (position, velocity, then effort if the layout has one)."""
        buffer = self.buffer
        sec = math.floor(stamp)
        STAMP.pack_into(buffer, self.stamp_at, sec, int((stamp - sec) * 1e9))
        for (packer, offset), sequence in zip(self.sequences, values, strict=True):
            packer.pack_into(buffer, offset, *sequence)
        return bytes(buffer)

    def round_trips(self, names: list[str], counts: list[int]) -> bool:
        """A message written here deserializes to what was written (checked once)."""
        stamp = 1_700_000_000.25
        sequences = [[0.5 + i + 10.0 * n for i in range(length)]
                     for n, length in enumerate(counts) if length]
        msg = deserialize_message(self.write(stamp, *sequences), JointState)
        read = [list(msg.position), list(msg.velocity), list(msg.effort)]
        return (msg.header.stamp.sec == 1_700_000_000
                and msg.header.stamp.nanosec == 250_000_000 and list(msg.name) == names
                and msg.header.frame_id == ''
                and [r for r in read if r] == sequences
                and [len(r) for r in read] == counts)


def unique_offset(data: bytes, pattern: bytes) -> int | None:
    """Where ``pattern`` is in ``data``, if it is there exactly once."""
    at = data.find(pattern)
    return at if at >= 0 and data.find(pattern, at + 1) < 0 else None
