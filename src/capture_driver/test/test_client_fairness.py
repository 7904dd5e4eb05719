"""The joint poll is not starved by a command stream.

Commands sent back to back (faster than the link takes them: a loaded machine, or serial at
115200 baud where one two-axis command is about one 100 Hz period) took the client lock
again as soon as they released it, and the poll waited hundreds of milliseconds (778 ms
measured) for its turn: joint_states stopped while the axes moved.

- Requests one at a time (``overlap`` off, the way back for a controller that drops what it
  queues): the poll takes the link lock, which is fair, so it waits for the command in
  progress only. Counted in commands, not in time.
- Requests overlapping (the default): the poll's getters, once the device has answered
  them with data, do not take the link lock at all. They go out and come back while a
  command holds the lock for as long as it likes.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest

from capture_driver.client import CaptureClient
from capture_driver.sim import CaptureSimulator
from gimbal_driver_common.transport import TcpStream
from gimbal_driver_testing import wait_for

POLL = [(name, axis) for axis in (1, 2) for name in ('MOT_GetLoadPosition',
                                                      'MOT_GetMotorSpeed')]


@pytest.fixture
def client() -> Iterator[CaptureClient]:
    sim = CaptureSimulator(tcp_port=0).start()
    client = CaptureClient(lambda: TcpStream('127.0.0.1', sim.tcp.port), timeout=0.5)
    client.connect()
    try:
        yield client
    finally:
        client.stop()
        sim.stop()


def test_one_at_a_time_a_poll_waits_for_the_command_in_progress_only(client) -> None:
    client.overlap = False
    sent, stop = [0], threading.Event()

    def stream() -> None:  # two-axis moves back to back, like CaptureDevice.move
        while not stop.is_set():
            with client.link_lock:
                for axis in (1, 2):
                    client.move_absolute(axis, 0.01 * (sent[0] % 100), 30.0, 300.0)
            sent[0] += 1

    thread = threading.Thread(target=stream, daemon=True)
    thread.start()
    try:
        wait_for(lambda: sent[0] > 5, 10.0, 'the command stream')
        during = []
        for _ in range(100):
            before = sent[0]
            client.read_many(POLL)
            during.append(sent[0] - before)
        assert max(during) <= 2, during  # the one in progress (and one that raced the ask)
    finally:
        stop.set()
        thread.join(5.0)


def test_overlapping_a_poll_goes_out_while_a_command_holds_the_link(client) -> None:
    assert client.overlap
    first = client.read_many(POLL)  # answered with data: trusted beside setters from now on
    assert all(value is not None for value in first)
    holding, release, polled = threading.Event(), threading.Event(), []

    def command_in_progress() -> None:
        with client.link_lock:
            client.move_absolute(1, 0.5, 30.0, 300.0)
            holding.set()
            release.wait(30.0)

    holder = threading.Thread(target=command_in_progress, daemon=True)
    holder.start()
    try:
        assert holding.wait(10.0)
        poller = threading.Thread(target=lambda: polled.append(client.read_many(POLL)),
                                  daemon=True)
        poller.start()
        poller.join(10.0)
        assert polled and all(value is not None for value in polled[0]), polled
        assert holder.is_alive()  # the command still holds the link lock
    finally:
        release.set()
        holder.join(5.0)
