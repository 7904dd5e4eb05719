"""Stream moves written without waiting (``CaptureClient.post_moves``), against the simulator
over TCP and the pty serial link: what goes out, who reads the ACKs, and what happens when
they are refused, lost, or overtaken by a stop."""

from __future__ import annotations

import pytest

from capture_driver.client import CaptureClient, DeviceNack, NotConnected
from capture_driver.protocol import BY_OPCODE, COMMANDS
from capture_driver.sim import CaptureSimulator, PedestalModel
from gimbal_driver_common.testing import wait_for
from gimbal_driver_common.transport import SerialStream, TcpStream

POLL = [(name, axis) for axis in (1, 2) for name in ('MOT_GetLoadPosition', 'MOT_GetMotorSpeed')]
SPEED, ACCELERATION = 60.0, 200.0


class CountingWrites:
    """Wraps a client's stream factory: counts the writes the client makes."""

    def __init__(self, factory) -> None:
        self.factory = factory
        self.writes = 0

    def __call__(self):
        stream = self.factory()
        write = stream.write

        def counted(data: bytes) -> None:
            self.writes += 1
            write(data)

        stream.write = counted
        return stream


@pytest.fixture
def sim():
    simulator = CaptureSimulator(PedestalModel(time_scale=8.0), tcp_port=0, pty=True).start()
    yield simulator
    simulator.stop()


def connect(sim, transport: str = 'tcp') -> tuple[CaptureClient, CountingWrites]:
    if transport == 'tcp':
        writes = CountingWrites(lambda: TcpStream('127.0.0.1', sim.tcp.port))
        client = CaptureClient(writes, timeout=0.3)
    else:
        writes = CountingWrites(lambda: SerialStream(sim.pty.port_name))
        client = CaptureClient(writes, timeout=0.3, expect_greeting=False)
    client.connect()
    return client, writes


def sent(sim, start: int) -> list[tuple[str, int]]:
    """(command, axis) of every request the simulator got since ``start``."""
    return [(BY_OPCODE[f.opcode].name, f.axis) for f in list(sim.model.requests)[start:]]


def at(client: CaptureClient, axis: int, target: float) -> None:
    def reached() -> bool:
        position, speed, _ = client.read_axis(axis)
        return abs(position - target) <= 1e-3 and speed == 0.0

    wait_for(reached, 10.0, f'axis {axis} at {target}')


@pytest.mark.parametrize('transport', ['tcp', 'pty'])
def test_a_stream_move_goes_out_in_one_write_once_the_axis_is_set_up(sim, transport):
    client, writes = connect(sim, transport)
    try:
        before = writes.writes
        assert not client.post_moves({1: (5.0, SPEED, ACCELERATION)})  # not set up yet
        assert writes.writes == before
        client.move_absolute(1, 5.0, SPEED, ACCELERATION)  # the set-up, and a TUM armed
        at(client, 1, 5.0)
        start, before = len(sim.model.requests), writes.writes
        assert client.post_moves({1: (9.0, SPEED, ACCELERATION)})
        assert writes.writes == before + 1
        assert not client.post_moves({1: (10.0, SPEED, ACCELERATION)})  # one at a time
        client.finish_posted()  # reads both ACKs, arms the next session's TUM
        assert sent(sim, start) == [('MOT_SendPosition', 1), ('MOT_Update', 1),
                                    ('MOT_SetTum', 1)]
        at(client, 1, 9.0)
        # another speed needs MOT_SetSpeed: not a stream move, sent by move_absolute
        assert not client.post_moves({1: (3.0, SPEED / 2, ACCELERATION)})
        assert client.post_moves({1: (3.0, SPEED, ACCELERATION)})
        client.finish_posted()
        at(client, 1, 3.0)
        assert client.stats['nacks'] == client.stats['timeouts'] == client.stats['stale'] == 0
    finally:
        client.stop()


def test_two_axes_in_one_post_and_the_poll_reads_the_acks_first(sim):
    client, writes = connect(sim)
    try:
        client.move_absolute(1, 1.0, SPEED, ACCELERATION)
        client.move_absolute(2, -1.0, SPEED, ACCELERATION)
        before = writes.writes
        assert client.post_moves({1: (4.0, SPEED, ACCELERATION), 2: (-4.0, SPEED, ACCELERATION)})
        assert writes.writes == before + 1
        client.read_many(POLL)  # the poll takes the link first: it reads the two ACKs
        assert client.stats['stale'] == 0
        client.finish_posted()
        at(client, 1, 4.0)
        at(client, 2, -4.0)
        assert client.post_moves({1: (5.0, SPEED, ACCELERATION)})  # both TUMs armed again
        client.finish_posted()
        at(client, 1, 5.0)
    finally:
        client.stop()


def test_a_refused_stream_move_is_reported_and_the_next_move_sets_up_again(sim):
    client, _ = connect(sim)
    try:
        client.move_absolute(1, 2.0, SPEED, ACCELERATION)
        sim.model.nack_next(0x16, COMMANDS['MOT_SendPosition'].opcode)
        assert client.post_moves({1: (6.0, SPEED, ACCELERATION)})
        with pytest.raises(DeviceNack, match=r'MOT_SendPosition \(axis 1\).*0x16'):
            client.finish_posted()
        at(client, 1, 2.0)  # the MOT_Update after it re-ran the previous profile
        assert not client.post_moves({1: (6.0, SPEED, ACCELERATION)})  # set-up forgotten
        start = len(sim.model.requests)
        client.move_absolute(1, 6.0, SPEED, ACCELERATION)
        assert ('MOT_SetPositionMode', 1) in sent(sim, start)
        at(client, 1, 6.0)
    finally:
        client.stop()


def test_a_stream_move_with_a_lost_ack_is_sent_again_one_request_at_a_time(sim):
    client, _ = connect(sim)
    try:
        client.move_absolute(1, 2.0, SPEED, ACCELERATION)
        sim.model.lose_replies(1)
        assert client.post_moves({1: (7.0, SPEED, ACCELERATION)})
        start = len(sim.model.requests)
        client.finish_posted()  # one ACK of two: which one is lost, the byte does not say
        assert ('MOT_SetPositionMode', 1) in sent(sim, start)  # the whole 7.1 set-up
        assert client.stats['incomplete_batches'] == 1 and client.connected
        at(client, 1, 7.0)
    finally:
        client.stop()


def test_a_stream_move_is_never_sent_again_after_a_stop(sim):
    client, _ = connect(sim)
    try:
        client.move_absolute(1, 0.5, SPEED, ACCELERATION)
        at(client, 1, 0.5)
        sim.model.lose_replies(1)
        assert client.post_moves({1: (40.0, SPEED, ACCELERATION)})
        client.stop_axis(1)  # reads what came of the post first, then stops
        start = len(sim.model.requests)
        client.finish_posted()  # the lost ACK would resend the move: not after a stop
        assert ('MOT_SendPosition', 1) not in sent(sim, start)
        wait_for(lambda: client.read_axis(1)[1] == 0.0, 5.0, 'axis 1 stopped')
    finally:
        client.stop()


@pytest.mark.parametrize('transport', ['tcp', 'pty'])
def test_a_controller_that_drops_queued_requests_gets_moves_one_at_a_time(sim, transport):
    sim.model.one_request_per_read = True
    client, _ = connect(sim, transport)
    try:
        target = 1.0
        client.move_absolute(1, target, SPEED, ACCELERATION)
        for _ in range(3):  # each post loses its MOT_Update: sent again, and counted
            target += 1.0
            assert client.post_moves({1: (target, SPEED, ACCELERATION)})
            client.finish_posted()
            at(client, 1, target)
        assert not client.batching
        assert not client.post_moves({1: (target + 1.0, SPEED, ACCELERATION)})
    finally:
        client.stop()


def test_a_link_lost_before_the_acks_is_reported_as_not_connected(sim):
    client, _ = connect(sim)
    try:
        client.move_absolute(1, 1.0, SPEED, ACCELERATION)
        assert client.post_moves({1: (3.0, SPEED, ACCELERATION)})
        client.close()
        with pytest.raises(NotConnected, match='stream move'):
            client.finish_posted()
        client.connect()
        assert not client.post_moves({1: (3.0, SPEED, ACCELERATION)})  # a new connection
    finally:
        client.stop()
