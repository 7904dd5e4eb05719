"""The simulator must survive any client input (it answers, ignores, never raises)."""

import contextlib

from hypothesis import given, settings
from hypothesis import strategies as st

from kessler_kos_driver.protocol import (
    FrameParser,
    ProtocolError,
    UserPassword,
    decode,
    encode_frame,
)
from kessler_kos_driver.sim import KosSession, SimSettings, SimulatedRig

frames = st.builds(
    lambda mid, mtype, payload: encode_frame(mid, mtype, payload),
    st.sampled_from([2, 7, 0x0B, 0x0F, 0x10, 0x11, 0x12, 0x1F, 0x26, 0x80, 0x81, 0x55]),
    st.sampled_from([0, 1, 2]),
    st.binary(max_size=48) | st.tuples(st.integers(0, 0x30), st.binary(max_size=16)).map(
        lambda t: bytes([t[0]]) + t[1]),
)


@settings(max_examples=200, deadline=None)
@given(st.lists(frames | st.binary(max_size=20), max_size=8))
def test_session_survives_arbitrary_input(chunks):
    device = SimulatedRig(SimSettings(password='pw', precalibrated=True, time_scale=50.0))
    session = KosSession(device)
    session.on_bytes(UserPassword('pw').encode())
    for chunk in chunks:
        reply = session.on_bytes(chunk)
        for frame in FrameParser().feed(reply):
            try:
                decode(frame)
            except ProtocolError as exc:  # the simulator must only emit valid frames
                raise AssertionError(f'simulator sent an undecodable frame: {exc}') from exc
    with contextlib.suppress(ConnectionAbortedError):   # how a session drops its link
        session.poll()                                  # (ResetDevice reboots the device)
    for motor in device.motors.values():
        lo, hi = motor.travel_limits()
        assert lo - 1e-6 <= motor.position <= hi + 1e-6
