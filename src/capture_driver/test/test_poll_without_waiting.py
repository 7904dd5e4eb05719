"""The joint poll without waiting (``CaptureDevice.request_read``, ``BatchedReads.ask_many``),
against the simulator over TCP, no ROS: the reader thread hands on a poll answered with
plain data; a poll answered otherwise, or not in time, is settled by the asking thread at
its next call with the rules of the waiting poll (asked again alone, the timeout counted).
Waits are "up to a timeout" for a condition, never timing assertions."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest

from capture_driver.device import CaptureDevice, CaptureSettings
from capture_driver.protocol import COMMANDS, ReplyCode
from capture_driver.sim import CaptureSimulator, PedestalModel
from gimbal_driver_common.device import JointSample
from gimbal_driver_testing import wait_for


class Samples:
    """What ``request_read`` delivered, and on which thread."""

    def __init__(self) -> None:
        self.taken: list[tuple[JointSample, str]] = []
        self.arrived = threading.Event()

    def __call__(self, sample: JointSample) -> None:
        self.taken.append((sample, threading.current_thread().name))
        self.arrived.set()

    def next(self, timeout: float = 10.0) -> tuple[JointSample, str]:
        assert self.arrived.wait(timeout), 'no sample delivered'
        self.arrived.clear()
        return self.taken[-1]


@pytest.fixture
def sim() -> Iterator[CaptureSimulator]:
    simulator = CaptureSimulator(PedestalModel(), tcp_port=0).start()
    yield simulator
    simulator.stop()


@pytest.fixture
def device(sim: CaptureSimulator) -> Iterator[CaptureDevice]:
    dev = CaptureDevice(CaptureSettings(
        joint_names=['pan', 'tilt'], axis_ids=[1, 2], joint_directions=[-1.0, 1.0],
        gear_ratios=[1.0, 1.0], transport='tcp', host='127.0.0.1', port=sim.tcp.port,
        keepalive_period=0.0, status_period=1000.0, request_timeout=0.5))
    dev.open()
    yield dev
    dev.close()


def polls_sent(sim: CaptureSimulator) -> int:
    opcode = COMMANDS['MOT_GetLoadPosition'].opcode
    with sim.model.lock:
        return sum(1 for frame in sim.model.requests if frame.opcode == opcode)


def test_the_reader_thread_hands_on_a_poll_answered_with_data(device, sim) -> None:
    samples = Samples()
    # the first poll of a connection waits (its getters may still answer with a byte)
    assert device.request_read(samples) is False
    assert device.read() is not None
    with sim.model.lock:
        sim.model.axes[1].position = 12.5  # degrees, pan counts clockwise
    assert device.request_read(samples) is True
    sample, thread = samples.next()
    assert thread != threading.current_thread().name  # not the asking thread
    assert sample.positions['pan'] == pytest.approx(-0.2182, abs=1e-3)
    assert set(sample.velocities) == {'pan', 'tilt'}


def test_a_poll_still_in_flight_is_not_asked_again(device, sim) -> None:
    samples = Samples()
    assert device.read() is not None
    sim.model.request_faults.mute('MOT_GetMotorSpeed')
    before = polls_sent(sim)
    assert device.request_read(samples) is True
    wait_for(lambda: polls_sent(sim) == before + 2, 10.0, 'the poll reaching the device')
    assert device.request_read(samples) is True  # within its timeout: waits, no new write
    assert polls_sent(sim) == before + 2
    assert samples.taken == []


def test_a_nacked_getter_is_asked_again_alone_by_the_next_call(device, sim) -> None:
    samples = Samples()
    assert device.read() is not None
    speed = COMMANDS['MOT_GetMotorSpeed'].opcode
    sim.model.nack_next(ReplyCode.EXECUTION_ERROR, opcode=speed)
    assert device.request_read(samples) is True
    # every getter answered, one with a NACK: not handed on by the reader
    wait_for(lambda: device.client.batch.asked is not None
             and device.client.batch.asked.answers is not None, 10.0, 'the answers')
    assert samples.taken == []
    assert device.request_read(samples) is True  # settles: the NACKed one asked alone
    sample, thread = samples.next()
    assert thread == threading.current_thread().name
    assert set(sample.positions) == {'pan', 'tilt'}


def test_a_poll_not_answered_in_time_is_settled_by_the_next_call(device, sim) -> None:
    samples = Samples()
    assert device.read() is not None
    incomplete = device.client.stats.get('incomplete_batches', 0)
    sim.model.lose_replies(2)  # pan's two getters: executed, never answered
    assert device.request_read(samples) is True
    asked = device.client.batch.asked
    assert asked is not None
    wait_for(asked.due, 10.0, 'the poll deadline')
    assert samples.taken == []  # the reader had nothing whole to hand on
    # settled here: the two unanswered getters asked again alone, answered this time
    assert device.request_read(samples) is True
    sample, thread = samples.next()
    assert thread == threading.current_thread().name
    assert set(sample.positions) == {'pan', 'tilt'}
    assert device.client.stats['incomplete_batches'] == incomplete + 1
    assert device.client.batch.asked is None
