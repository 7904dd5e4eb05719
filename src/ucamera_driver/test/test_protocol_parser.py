"""Stream parser: resynchronisation after noise, chunking, corrupted bytes (hypothesis)."""

import contextlib
import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ucamera_driver.protocol import (
    SYNC_BYTE,
    AnglesReport,
    Frame,
    FrameParser,
    ModeReport,
    PayloadError,
    ProtocolError,
    RangeError,
    SetAngles,
    decode_packet,
    expected_payload_length,
)
from ucamera_driver.protocol.packets import ALL_PACKETS

FUZZ = settings(
    max_examples=200, derandomize=True, deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)

frames_strategy = st.builds(
    Frame,
    category=st.integers(0, 255),
    packet_id=st.integers(0, 255),
    payload=st.binary(max_size=40),
)
noise_strategy = st.binary(max_size=120)


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    chunks, last = [], 0
    for point in [*points, len(data)]:
        chunks.append(data[last:point])
        last = point
    return chunks


@FUZZ
@given(frames=st.lists(frames_strategy, max_size=6), cuts=st.lists(st.integers(0, 10_000)))
def test_any_chunking_gives_the_same_frames(frames, cuts) -> None:
    wire = b"".join(f.encode() for f in frames)
    parser = FrameParser()
    out = []
    for chunk in split(wire, cuts):
        out.extend(parser.feed(chunk))
    assert out == frames
    assert parser.stats.checksum_errors == 0


@FUZZ
@given(
    noise=st.lists(st.binary(max_size=40).map(lambda b: b.replace(bytes([SYNC_BYTE]), b"")),
                   min_size=1, max_size=6),
    frames=st.lists(frames_strategy, min_size=1, max_size=5),
)
def test_noise_without_sync_never_hides_a_frame(noise, frames) -> None:
    wire = b"".join(n + f.encode() for n, f in zip(noise, frames, strict=False))
    parser = FrameParser()
    assert parser.feed(wire) == frames[: len(noise)]


@FUZZ
@given(
    pieces=st.lists(st.tuples(noise_strategy, frames_strategy), min_size=1, max_size=5),
    cuts=st.lists(st.integers(0, 10_000), max_size=8),
)
def test_resync_after_arbitrary_noise(pieces, cuts) -> None:
    """Whatever the noise (sync bytes included), every real frame is recovered
    unless a false header in the noise happens to carry a valid checksum, in
    which case that spurious frame shows up instead (1 in 65536 per false sync)."""
    wire = b"".join(noise + frame.encode() for noise, frame in pieces)
    wire += bytes(300)  # flush: lets any false long header run out
    parser = FrameParser()
    out = []
    for chunk in split(wire, cuts):
        out.extend(parser.feed(chunk))
    real = [frame for _, frame in pieces]
    spurious = [f for f in out if f not in real]
    if not spurious:
        assert out == real


@FUZZ
@given(data=st.binary(max_size=600))
def test_decoders_only_raise_codec_errors(data) -> None:
    parser = FrameParser(expected_payload_length)
    for frame in parser.feed(data):
        with contextlib.suppress(ProtocolError):
            decode_packet(frame)
    for cls in ALL_PACKETS:
        with contextlib.suppress(PayloadError, RangeError):
            cls.from_payload(data[: cls.payload_length()])


@FUZZ
@given(
    pan=st.floats(-math.radians(327.67), math.radians(327.67)),
    tilt=st.floats(-math.radians(327.67), math.radians(327.67)),
)
def test_angles_round_trip_within_one_count(pan, tilt) -> None:
    decoded = decode_packet(FrameParser().feed(SetAngles(pan, tilt).encode())[0])
    assert abs(decoded.pan - pan) <= math.radians(0.005) + 1e-12
    assert abs(decoded.tilt - tilt) <= math.radians(0.005) + 1e-12


def test_corrupted_byte_drops_only_that_frame() -> None:
    first = AnglesReport(0.1, 0.2).encode()
    second = bytearray(ModeReport(1).encode())
    second[4] ^= 0x40
    third = AnglesReport(-0.1, 0.3).encode()
    parser = FrameParser(expected_payload_length)
    frames = parser.feed(first + bytes(second) + third)
    assert [decode_packet(f) for f in frames] == [
        decode_packet(FrameParser().feed(first)[0]),
        decode_packet(FrameParser().feed(third)[0]),
    ]
    assert parser.stats.checksum_errors == 1


def test_wrong_length_for_known_packet_is_rejected_at_the_header() -> None:
    # A false header announcing 200 bytes for Report Angles (6 bytes) must not
    # make the parser wait for 200 bytes: the next real frame comes out at once.
    real = AnglesReport(0.5, -0.5).encode()
    parser = FrameParser(expected_payload_length)
    frames = parser.feed(bytes([SYNC_BYTE, 0x09, 0x06, 200]) + real)
    assert len(frames) == 1
    assert parser.stats.length_errors == 1
    assert parser.pending == 0


def test_partial_frame_waits_for_the_rest() -> None:
    wire = ModeReport(3).encode()
    parser = FrameParser()
    assert parser.feed(wire[:5]) == []
    assert parser.pending == 5
    assert len(parser.feed(wire[5:])) == 1
