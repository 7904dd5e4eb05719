"""The joint poll is not starved by a command stream (the client's request lock is fair).

Commands sent back to back (faster than the link takes them: a loaded machine, or serial at
115200 baud where one two-axis command is about one 100 Hz period) took the client lock
again as soon as they released it, and the poll waited hundreds of milliseconds (778 ms
measured) for its turn: joint_states stopped while the axes moved. Counted here in commands,
not in time: while the poll waits, at most the command in progress finishes.
"""

from __future__ import annotations

import threading

from capture_driver.client import CaptureClient
from capture_driver.sim import CaptureSimulator, PedestalModel
from gimbal_driver_common.testing import wait_for
from gimbal_driver_common.transport import TcpStream

POLL = [(name, axis) for axis in (1, 2) for name in ('MOT_GetLoadPosition',
                                                      'MOT_GetMotorSpeed')]


def test_a_poll_waits_for_the_command_in_progress_only() -> None:
    sim = CaptureSimulator(PedestalModel(), tcp_port=0).start()
    client = CaptureClient(lambda: TcpStream('127.0.0.1', sim.tcp.port), timeout=0.5)
    client.connect()
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
        client.stop()
        sim.stop()
