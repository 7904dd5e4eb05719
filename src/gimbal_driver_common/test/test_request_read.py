"""A device that polls without waiting (``Device.request_read``): the controller's device
thread writes the request, the link's reader thread hands the sample over, and the
controller takes it there (watches, publication) as it takes a sample from ``read()``."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Sequence

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.device import Device, DeviceInfo, JointSample, Moves
from gimbal_driver_common.errors import DeviceTimeout
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.controller_rig import running_controller

JOINTS = ['pan', 'tilt']


def config() -> ControllerConfig:
    return ControllerConfig(list(JOINTS), {j: JointLimits(-1.0, 1.0, 2.0) for j in JOINTS},
                            publish_rate=500.0, reconnect_period=0.01)


class ReaderPolledDevice(Device):
    """Answers each request on its own 'reader' thread; ``read()`` must never be used."""

    def __init__(self) -> None:
        super().__init__()
        self.positions = dict.fromkeys(JOINTS, 0.0)
        self.requests: queue.Queue[Callable[[JointSample], object] | None] = queue.Queue()
        self.request_threads: set[str] = set()
        self.fail_next: BaseException | None = None
        self.reads = 0
        self.reader = threading.Thread(target=self._answer, name='fake-reader', daemon=True)
        self.reader.start()

    def _answer(self) -> None:
        while (deliver := self.requests.get()) is not None:
            self.positions['pan'] += 0.01
            deliver(JointSample(dict(self.positions), dict.fromkeys(JOINTS, 0.0)))

    def open(self) -> DeviceInfo:
        return DeviceInfo('fake', 'SN1', '1.0')

    def close(self) -> None:
        pass

    def request_read(self, deliver: Callable[[JointSample], object]) -> bool:
        self.request_threads.add(threading.current_thread().name)
        failed, self.fail_next = self.fail_next, None
        if failed is not None:
            raise failed
        self.requests.put(deliver)
        return True

    def read(self) -> JointSample:
        self.reads += 1
        raise AssertionError('polled with read() although request_read asked')

    def move(self, moves: Moves) -> None:
        pass

    def jog(self, velocities: dict[str, float]) -> None:
        pass

    def stop(self, joints: Sequence[str] | None = None) -> None:
        pass


@pytest.fixture
def rig():
    device = ReaderPolledDevice()
    published: list[tuple[str, JointSample]] = []
    try:
        with running_controller(device, config(), first_sample=False,
                                on_sample=lambda s: published.append(
                                    (threading.current_thread().name, s))) as ctl:
            yield ctl, device, published
    finally:
        device.requests.put(None)


def test_the_reader_threads_sample_is_taken_and_published_there(rig) -> None:
    ctl, device, published = rig
    wait_for(lambda: len(published) >= 5, 5.0, 'samples published')
    assert {name for name, _ in published} == {'fake-reader'}
    assert device.request_threads == {'device'} and device.reads == 0
    wait_for(lambda: ctl.latest is not None and ctl.latest.positions['pan'] > 0.0, 5.0,
             'the latest sample')
    # the watches see them: a stop is confirmed by these samples (the axis at rest)
    assert ctl.stop().startswith('all axes stopped and at rest')


def test_a_failed_poll_request_loses_the_link_and_it_reconnects(rig) -> None:
    ctl, device, _ = rig
    wait_for(lambda: ctl.latest is not None, 5.0, 'a first sample')
    device.fail_next = DeviceTimeout('no reply to GET within 0.2 s (2 polls in a row)')
    wait_for(lambda: ctl.reconnects == 1 and ctl.connected, 5.0, 'the reconnect')
    assert device.reads == 0


def newer_samples(ctl: GimbalController, count: int) -> None:
    """Wait until the controller took ``count`` samples more."""
    for _ in range(count):
        wait_for(lambda seen=ctl.latest: ctl.latest is not seen, 5.0, 'a newer sample')


def test_inactive_the_samples_are_watched_not_published(rig) -> None:
    ctl, _, published = rig
    wait_for(lambda: ctl.latest is not None, 5.0, 'a first sample')
    ctl.active = False
    newer_samples(ctl, 2)  # one taken as it was deactivated may still have been published
    count = len(published)
    newer_samples(ctl, 3)
    assert len(published) == count
