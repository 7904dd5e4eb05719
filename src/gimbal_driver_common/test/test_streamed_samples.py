"""A streamed device's samples are taken on the thread that receives them
(``streamed_samples``): read, watched and published there, at most ``publish_rate``; the
controller's device thread reads only when the stream is quiet or the link fails."""

from __future__ import annotations

import queue
import threading
from collections.abc import Sequence

import pytest

from gimbal_driver_common.controller import ControllerConfig
from gimbal_driver_common.device import Device, DeviceInfo, JointSample, Moves
from gimbal_driver_common.errors import LinkError
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.streamed_samples import StreamedSamples
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.controller_rig import running_controller

JOINTS = ['pan', 'tilt']


class StreamingDevice(Device):
    """Streams a sample for each item put on ``frames`` from its 'fake-receiver' thread;
    records which thread read its cache."""

    streamed = True

    def __init__(self) -> None:
        super().__init__()
        self.frames: queue.Queue[float | None] = queue.Queue()
        self.latest: JointSample | None = None
        self.read_threads: list[str] = []
        self.link_down = False
        self.opens = 0
        self.receiver = threading.Thread(target=self._receive, name='fake-receiver',
                                         daemon=True)
        self.receiver.start()

    def _receive(self) -> None:
        while (stamp := self.frames.get()) is not None:
            self.latest = JointSample({'pan': stamp, 'tilt': 0.0}, dict.fromkeys(JOINTS, 0.0),
                                      stamp=stamp)
            self.notify_data()

    def open(self) -> DeviceInfo:
        self.opens += 1
        self.link_down = False
        return DeviceInfo('fake', 'SN1', '1.0')

    def link_healthy(self) -> bool:
        if self.link_down:
            raise LinkError('fake link: peer reset')
        return True

    def read(self) -> JointSample | None:
        self.read_threads.append(threading.current_thread().name)
        return self.latest

    def move(self, moves: Moves) -> None:
        pass

    def jog(self, velocities: dict[str, float]) -> None:
        pass

    def stop(self, joints: Sequence[str] | None = None) -> None:
        pass


class Taken:
    """The controller's side: each sample taken, with its thread."""

    def __init__(self) -> None:
        self.samples: list[tuple[str, JointSample]] = []

    def __call__(self, sample: JointSample, read_at: float) -> bool:
        self.samples.append((threading.current_thread().name, sample))
        return True

    def stamps(self) -> list[float]:
        return [sample.stamp for _, sample in self.samples]


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def streamed(device: Device, taken: Taken, clock: Clock, rate: float = 50.0,
             taking: bool = True) -> StreamedSamples:
    return StreamedSamples(device, taken, lambda: taking, lambda: 1.0 / rate, clock,
                           monotonic=clock)


def sample(stamp: float) -> JointSample:
    return JointSample({'pan': stamp, 'tilt': 0.0}, dict.fromkeys(JOINTS, 0.0), stamp=stamp)


class CacheDevice(StreamingDevice):
    """No receiver thread: the test sets ``latest`` and calls on_data itself."""

    def __init__(self) -> None:
        super().__init__()
        self.frames.put(None)


def test_each_new_sample_is_taken_once_and_a_too_early_one_left_to_the_device_thread() -> None:
    device, taken, clock = CacheDevice(), Taken(), Clock()
    samples = streamed(device, taken, clock, rate=50.0)
    device.latest = sample(1.0)
    assert samples.on_data() and taken.stamps() == [1.0]
    device.latest = sample(2.0)
    clock.now += 0.005  # 5 ms after the last publication, at 50 Hz: too soon
    assert not samples.on_data()  # declined: the device thread takes it once due
    assert taken.stamps() == [1.0]
    assert samples.hold() == pytest.approx(0.9 * 0.020 - 0.5 * 0.020 - 0.005)
    clock.now += samples.hold()
    assert samples.take() and taken.stamps() == [1.0, 2.0]
    clock.now += 0.020
    assert samples.on_data() and taken.stamps() == [1.0, 2.0]  # the same stamp: not again


def test_an_early_sample_after_a_late_one_goes_at_once_and_the_rate_stays_capped() -> None:
    """Jitter (a sample 15 ms after one that came 25 ms late, at 50 Hz) costs no wait; so
    does a device a hair faster than publish_rate (no drift builds up); a device streaming
    at twice publish_rate is published at most at 1/0.9 of it."""
    device, taken, clock = CacheDevice(), Taken(), Clock()
    samples = streamed(device, taken, clock, rate=50.0)
    for stamp, after in enumerate([0.0, 0.025, 0.015, 0.020, 0.025, 0.015], start=1):
        clock.now += after
        device.latest = sample(float(stamp))
        assert samples.on_data(), f'sample {stamp} held back'
    assert taken.stamps() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    for stamp in range(7, 507):  # 10 s of a device 0.5 % faster than publish_rate
        clock.now += 0.020 * 0.995
        device.latest = sample(float(stamp))
        assert samples.on_data(), f'sample {stamp} held back'
    published = 0
    for stamp in range(507, 607):  # 1 s at 100 Hz: one a slot, the rest declined
        clock.now += 0.010
        device.latest = sample(float(stamp))
        published += samples.on_data()
    assert 50 <= published <= 57


def test_the_receive_thread_declines_while_the_link_is_not_up_or_a_read_raises() -> None:
    device, taken, clock = CacheDevice(), Taken(), Clock()
    device.latest = sample(1.0)
    assert not streamed(device, taken, clock, taking=False).on_data()
    device.link_down = True
    samples = streamed(device, taken, clock)
    assert not samples.on_data()
    with pytest.raises(LinkError, match='peer reset'):
        samples.take()  # the device thread's take: the reason, to lose the link with
    assert taken.samples == []


# ------------------------------------------------------------------ in a controller
def config(rate: float) -> ControllerConfig:
    return ControllerConfig(list(JOINTS), {j: JointLimits(-1.0, 1.0, 2.0) for j in JOINTS},
                            publish_rate=rate, reconnect_period=0.01)


@pytest.fixture
def rig():
    device = StreamingDevice()
    published: list[tuple[str, JointSample]] = []
    try:
        with running_controller(device, config(50.0), first_sample=False,
                                on_sample=lambda s: published.append(
                                    (threading.current_thread().name, s))) as ctl:
            yield ctl, device, published
    finally:
        device.frames.put(None)


def test_a_streamed_sample_is_published_on_the_receive_thread(rig) -> None:
    ctl, device, published = rig
    device.frames.put(1.0)
    wait_for(lambda: published, 5.0, 'the sample published')
    assert [(name, s.stamp) for name, s in published] == [('fake-receiver', 1.0)]
    assert ctl.latest is not None and ctl.latest.stamp == 1.0
    assert device.read_threads[0] == 'fake-receiver'


def test_a_sample_held_back_as_too_soon_is_published_once_the_stream_is_quiet(rig) -> None:
    ctl, device, published = rig
    ctl.set_publish_rate(2.0)  # a 0.5 s period: the second sample is certainly too soon
    device.frames.put(1.0)
    device.frames.put(2.0)
    wait_for(lambda: [s.stamp for _, s in published] == [1.0, 2.0], 10.0,
             'both samples published, the held one once it was due')
    assert published[0][0] == 'fake-receiver'


def test_a_link_the_receive_thread_finds_down_is_lost_and_reconnected(rig) -> None:
    ctl, device, published = rig
    device.frames.put(1.0)
    wait_for(lambda: published, 5.0, 'a first sample')
    device.link_down = True
    device.frames.put(2.0)
    wait_for(lambda: ctl.reconnects == 1 and ctl.connected, 5.0, 'the reconnect')
    assert device.opens == 2
    device.frames.put(3.0)
    wait_for(lambda: published[-1][1].stamp == 3.0, 5.0, 'samples after the reconnect')
