"""The shared request faults on the U-Camera simulator, over its pseudo-terminal: a muted UCSP
request is never answered and a delayed one is answered late, while the other requests are
answered at once and the telemetry streams on; ``clear`` restores."""

from __future__ import annotations

import time

import pytest

from gimbal_driver_common.registry import driver_of_package
from gimbal_driver_common.sim_handle import make_handle
from gimbal_driver_common.transport import SerialStream
from gimbal_driver_testing import wait_for
from ucamera_driver.protocol import (
    AntennaPositionReport,
    AntennaPositionRequest,
    FrameParser,
    Packet,
    TelemetryRateReport,
    TelemetryRateRequest,
    VersionReport,
    VersionRequest,
    decode_packet,
    expected_payload_length,
)
from ucamera_driver.sim import SimConfig, UCameraSim

DELAY_S = 0.4
#: the answers these tests wait for (the gimbal also streams its periodic reports)
ANSWERS = (AntennaPositionReport, TelemetryRateReport, VersionReport)


class Link:
    """The host side of the pty: requests out, the answers in, each stamped with the time it
    arrived; counts the periodic reports that came too."""

    def __init__(self, path: str) -> None:
        self.stream = SerialStream(path)
        self.stream.open()
        self.parser = FrameParser(expected_payload_length)
        self.pending: list[Packet] = []
        self.reports = 0

    def send(self, packet: Packet) -> float:
        sent = time.monotonic()  # before the write: the device may act before it returns
        self.stream.write(packet.encode())
        return sent

    def answer(self, timeout: float = 10.0) -> tuple[str, float]:
        def next_answer() -> Packet | None:
            if not self.pending:
                for frame in self.parser.feed(self.stream.read(4096, 0.05)):
                    packet = decode_packet(frame)
                    if isinstance(packet, ANSWERS):
                        self.pending.append(packet)
                    else:
                        self.reports += 1
            return self.pending.pop(0) if self.pending else None

        packet = wait_for(next_answer, timeout, 'an answer')
        return type(packet).__name__, time.monotonic()

    def names(self, count: int) -> list[str]:
        return [self.answer()[0] for _ in range(count)]

    def close(self) -> None:
        self.stream.close()


@pytest.fixture
def rig():
    with UCameraSim(SimConfig(init_time=0.1)) as sim:
        link = Link(sim.port_name)
        yield sim, link
        link.close()


def test_a_muted_request_is_never_answered_while_others_are(rig) -> None:
    sim, link = rig
    assert sim.command('mute VersionRequest') == 'ok VersionRequest never answered'
    link.send(VersionRequest())
    link.send(TelemetryRateRequest())
    link.send(VersionRequest())
    link.send(AntennaPositionRequest())
    # every answer belongs to a later request: the VersionRequests got none
    assert link.names(2) == ['TelemetryRateReport', 'AntennaPositionReport']
    assert sim.model.received['VersionRequest'] == 2  # received as the gimbal saw them


def test_a_delayed_request_is_answered_late_and_others_meanwhile(rig) -> None:
    sim, link = rig
    assert sim.command(f'delay telemetryraterequest {DELAY_S}') == \
        f'ok TelemetryRateRequest answered {DELAY_S:g} s late'
    sent = link.send(TelemetryRateRequest())
    link.send(VersionRequest())
    assert link.answer()[0] == 'VersionReport'
    reports_before = link.reports
    name, arrived = link.answer()
    assert name == 'TelemetryRateReport'
    assert arrived - sent >= DELAY_S  # not before the delay
    assert link.reports > reports_before  # the telemetry went on while it waited


def test_clear_restores_every_answer(rig) -> None:
    sim, link = rig
    sim.command('mute VersionRequest')
    sim.command('delay TelemetryRateRequest 5')
    assert sim.command('clear') == 'ok'
    for packet in (VersionRequest(), TelemetryRateRequest(), AntennaPositionRequest()):
        link.send(packet)
    assert link.names(3) == ['VersionReport', 'TelemetryRateReport', 'AntennaPositionReport']


def test_an_unknown_packet_name_is_refused_with_the_requests(rig) -> None:
    sim, _ = rig
    assert sim.command('mute SetZoomTurbo') == (
        "error mute: unknown request 'SetZoomTurbo'; known: AntennaPositionRequest, "
        'SetAngles, SetMode, SetRates, TelemetryRateRequest, VersionRequest')


def test_the_sim_handle_logs_a_muted_request_as_received(tmp_path) -> None:
    handle = make_handle(driver_of_package('ucamera_driver'), tmp_path)
    handle.start()
    link = Link(handle.server.port_name)
    try:
        handle.mute('VersionRequest')
        link.send(VersionRequest())
        link.send(TelemetryRateRequest())
        assert link.answer()[0] == 'TelemetryRateReport'
        logged = [r.split()[0] for r in handle.requests()]
        assert logged[-2:] == ['VersionRequest', 'TelemetryRateRequest']
        handle.clear()
        link.send(VersionRequest())
        assert link.answer()[0] == 'VersionReport'
    finally:
        link.close()
        handle.stop()
