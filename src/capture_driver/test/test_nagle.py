"""A controller whose TCP stack leaves Nagle's algorithm on (the simulator's ``--nagle``)
still gets ``publish_rate``: the batched poll's replies come one segment each, and each
after the first waits for the ACK of the one before, which the client must not delay.

Asserted on the device-side poll (the median duration of a whole poll against the
period of the default 50 Hz ``publish_rate``), not on wall-clock topic rates: a loaded
machine stretches a few polls, never the median by 40 ms per reply. The rate itself is
in the benchmark (``bench/run.py capture``: ``nagle_poll_rate``).
"""

from __future__ import annotations

import statistics
import time

import pytest

from capture_driver.device import CaptureDevice, CaptureSettings
from capture_driver.sim import CaptureSimulator, PedestalModel
from gimbal_driver_common import transport

PUBLISH_RATE = 50.0


def poll_durations(sim: CaptureSimulator, polls: int = 21) -> list[float]:
    settings = CaptureSettings(
        joint_names=['pan', 'tilt'], axis_ids=[1, 2], joint_directions=[-1.0, 1.0],
        gear_ratios=[1.0, 1.0], transport='tcp', keepalive_period=0.0, default_speed=1.0,
        acceleration=6.0, status_period=0.1, host='127.0.0.1', port=sim.tcp.port)
    device = CaptureDevice(settings)
    device.open()
    try:
        device.read()  # the first poll also reads what is read once
        durations = []
        for _ in range(polls):
            start = time.monotonic()
            assert device.read() is not None
            durations.append(time.monotonic() - start)
        assert device.client.batching, 'the poll fell back to one request at a time'
        return durations
    finally:
        device.close()


@pytest.fixture
def nagle_sim():
    with CaptureSimulator(PedestalModel(), tcp_port=0, nagle=True) as simulator:
        yield simulator


def test_the_batched_poll_fits_the_publish_period_against_a_nagle_controller(nagle_sim):
    median = statistics.median(poll_durations(nagle_sim))
    assert median < 1.0 / PUBLISH_RATE, (
        f'a poll takes {median * 1e3:.1f} ms (median) against a controller with Nagle on: '
        f'more than the {1e3 / PUBLISH_RATE:.0f} ms period of {PUBLISH_RATE:g} Hz')


@pytest.mark.skipif(transport.QUICKACK is None, reason='TCP_QUICKACK is Linux only')
def test_the_nagle_simulator_reproduces_the_delayed_ack_wait(nagle_sim, monkeypatch):
    """Without the client's immediate ACK the same poll waits for delayed ACKs: the
    simulator's flag really plays the trap the test above guards against."""
    monkeypatch.setattr(transport, 'QUICKACK', None)
    median = statistics.median(poll_durations(nagle_sim, polls=5))
    assert median > 1.0 / PUBLISH_RATE
