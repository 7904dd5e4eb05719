"""The shared request faults on the kOS simulator, over TCP and the simulated USB HID link: a
muted request message is never answered and a delayed one is answered late, while the other
requests are answered at once; ``clear`` restores."""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from gimbal_driver_common.registry import driver_of_package
from gimbal_driver_common.sim_handle import make_handle
from gimbal_driver_common.transport import TcpStream
from gimbal_driver_testing import wait_for
from kessler_kos_driver.protocol import (
    DeviceGuid,
    DeviceInfo,
    FrameParser,
    GetDeviceGuid,
    GetDeviceInfo,
    GetSoftwareId,
    Message,
    SoftwareId,
    UserPassword,
    decode,
)
from kessler_kos_driver.protocol.usb import REPORT_SIZE, ReportReassembler, encode_reports
from kessler_kos_driver.sim import KosSimulator, SimHidDevice, SimSettings, SimulatedRig

PASSWORD = 'hunter2'
DELAY_S = 0.4
#: the answers these tests wait for (the device also streams notifications)
ANSWERS = (DeviceGuid, DeviceInfo, SoftwareId)


class Link:
    """The host side of one link: request messages out, the answers in, each stamped with
    the time it arrived (notifications skipped)."""

    def __init__(self, write: Callable[[bytes], None], read: Callable[[], bytes]) -> None:
        self._write, self._read = write, read
        self.parser = FrameParser()
        self.pending: list[Message] = []

    def send(self, message: Message) -> float:
        sent = time.monotonic()  # before the write: the device may act before it returns
        self._write(message.encode())
        return sent

    def answer(self, timeout: float = 10.0) -> tuple[str, float]:
        def next_answer() -> Message | None:
            if not self.pending:
                self.pending += [m for m in map(decode, self.parser.feed(self._read()))
                                 if isinstance(m, ANSWERS)]
            return self.pending.pop(0) if self.pending else None

        message = wait_for(next_answer, timeout, 'an answer')
        return type(message).__name__, time.monotonic()

    def names(self, count: int) -> list[str]:
        return [self.answer()[0] for _ in range(count)]


@pytest.fixture
def tcp():
    simulator = KosSimulator(SimSettings(password=PASSWORD), port=0).start()
    stream = TcpStream('127.0.0.1', simulator.port)
    stream.open()
    link = Link(stream.write, lambda: stream.read(65536, 0.05))
    link.send(UserPassword(PASSWORD))
    yield simulator, link
    stream.close()
    simulator.stop()


def test_a_muted_request_is_never_answered_while_others_are(tcp) -> None:
    simulator, link = tcp
    assert simulator.command('mute GetDeviceGuid') == 'ok GetDeviceGuid never answered'
    link.send(GetDeviceGuid())
    link.send(GetDeviceInfo())
    link.send(GetDeviceGuid())
    link.send(GetSoftwareId())
    # every answer belongs to a later request: the GetDeviceGuid got none
    assert link.names(2) == ['DeviceInfo', 'SoftwareId']


def test_a_delayed_request_is_answered_late_and_others_meanwhile(tcp) -> None:
    simulator, link = tcp
    assert simulator.command(f'delay getdeviceguid {DELAY_S}') == \
        f'ok GetDeviceGuid answered {DELAY_S:g} s late'
    sent = link.send(GetDeviceGuid())
    link.send(GetDeviceInfo())
    link.send(GetSoftwareId())
    assert link.names(2) == ['DeviceInfo', 'SoftwareId']
    name, arrived = link.answer()
    assert name == 'DeviceGuid' and arrived - sent >= DELAY_S  # not before the delay


def test_clear_restores_every_answer(tcp) -> None:
    simulator, link = tcp
    simulator.command('mute GetDeviceGuid')
    simulator.command('delay GetDeviceInfo 5')
    assert simulator.command('clear') == 'ok'
    for message in (GetDeviceGuid(), GetDeviceInfo(), GetSoftwareId()):
        link.send(message)
    assert link.names(3) == ['DeviceGuid', 'DeviceInfo', 'SoftwareId']


def test_an_unknown_message_name_is_refused_with_the_requests(tcp) -> None:
    simulator, _ = tcp
    assert simulator.command('mute TakePicture') == (
        "error mute: unknown request 'TakePicture'; known: GetDeviceGuid, "
        'GetDeviceInfo, GetLedStatus, GetMotorInfo, GetNetworkInfo, GetSoftwareId, '
        'GetTrajectoryData, RapidToFirstKeyFrame, SetPositionSpeedAcceleration, '
        'StartPlayback, StopPlayback')


def test_a_delayed_answer_comes_late_over_usb_too() -> None:
    rig = SimulatedRig(SimSettings(password='not-used-on-usb'))
    hid = SimHidDevice(rig)
    hid.open()
    reassembler = ReportReassembler()

    def write(frame: bytes) -> None:
        for report in encode_reports(frame, REPORT_SIZE):
            hid.write(report)

    link = Link(write, lambda: reassembler.feed(bytes(hid.read(REPORT_SIZE + 1, 50))))
    rig.request_faults.delay('GetDeviceGuid', DELAY_S)
    sent = link.send(GetDeviceGuid())
    link.send(GetSoftwareId())
    assert link.answer()[0] == 'SoftwareId'
    name, arrived = link.answer()
    assert name == 'DeviceGuid' and arrived - sent >= DELAY_S
    hid.close()


def test_the_sim_handle_logs_a_muted_request_as_received(tmp_path) -> None:
    handle = make_handle(driver_of_package('kessler_kos_driver'), tmp_path)
    handle.start()
    stream = TcpStream('127.0.0.1', handle.port)
    stream.open()
    link = Link(stream.write, lambda: stream.read(65536, 0.05))
    try:
        link.send(UserPassword(handle.spec.password))
        handle.mute('GetDeviceGuid')
        link.send(GetDeviceGuid())
        link.send(GetSoftwareId())
        assert link.answer()[0] == 'SoftwareId'
        assert handle.requests()[-2:] == ['GetDeviceGuid', 'GetSoftwareId']
        handle.clear()
        link.send(GetDeviceGuid())
        assert link.answer()[0] == 'DeviceGuid'
    finally:
        stream.close()
        handle.stop()
