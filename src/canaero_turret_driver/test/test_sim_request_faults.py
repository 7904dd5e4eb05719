"""The shared request faults on the turret simulator, over slcan on its pseudo-terminal: a
muted node service is never answered and a delayed one is answered late, while the other
services are answered at once and the broadcasts go on; ``clear`` restores."""

from __future__ import annotations

import time

import can
import pytest

from canaero_turret_driver.protocol import CanAerospaceMessage
from canaero_turret_driver.protocol import nodeservice as ns
from canaero_turret_driver.protocol.identifiers import TURRET_NODE_ID
from canaero_turret_driver.sim import SlcanSession, TurretSimulator, encode_slcan, make_control
from gimbal_driver_common.registry import driver_of_package
from gimbal_driver_common.sim_handle import make_handle
from gimbal_driver_common.sim_server import PtySimServer
from gimbal_driver_common.transport import SerialStream
from gimbal_driver_testing import wait_for

DELAY_S = 0.4


class Slcan:
    """The host side of the slcan adapter: service requests out, service responses in
    (by service name), each stamped with the time it arrived; counts the broadcasts."""

    def __init__(self, path: str) -> None:
        self.stream = SerialStream(path)
        self.stream.open()
        self.stream.write(b'O\r')
        self.buffer = b''
        self.pending: list[str] = []
        self.broadcasts = 0

    def send(self, request: CanAerospaceMessage) -> float:
        sent = time.monotonic()  # before the write: the device may act before it returns
        self.stream.write(encode_slcan(can.Message(
            arbitration_id=request.can_id, is_extended_id=False, data=request.to_bytes())))
        return sent

    def _take(self) -> None:
        self.buffer += self.stream.read(4096, 0.05)
        *records, self.buffer = self.buffer.split(b'\r')
        for record in records:
            if not record.startswith(b't'):
                continue  # the adapter's own answers (z, empty)
            can_id, dlc = int(record[1:4], 16), int(record[4:5])
            data = bytes.fromhex(record[5:5 + 2 * dlc].decode())
            service = ns.service_channel_of(can_id)
            if service is None:
                self.broadcasts += 1
            elif not service[1]:
                message = CanAerospaceMessage.from_frame(can_id, data)
                self.pending.append(ns.ServiceCode(message.service_code).name)

    def response(self, timeout: float = 10.0) -> tuple[str, float]:
        def next_response() -> str | None:
            if not self.pending:
                self._take()
            return self.pending.pop(0) if self.pending else None

        name = wait_for(next_response, timeout, 'a service response')
        return name, time.monotonic()

    def names(self, count: int) -> list[str]:
        return [self.response()[0] for _ in range(count)]

    def close(self) -> None:
        self.stream.close()


@pytest.fixture
def rig():
    simulator = TurretSimulator()
    server = PtySimServer(lambda: SlcanSession(simulator)).start()
    control = make_control(simulator, server)
    link = Slcan(server.port_name)
    yield control, link
    link.close()
    server.stop()


def ids() -> CanAerospaceMessage:
    return ns.ids_request(TURRET_NODE_ID)


def fps() -> CanAerospaceMessage:
    return ns.fps_request(TURRET_NODE_ID, 0)


def tis() -> CanAerospaceMessage:
    return ns.tis_request(TURRET_NODE_ID, 0, 0)


def test_a_muted_service_is_never_answered_while_others_are(rig) -> None:
    control, link = rig
    assert control.execute('mute IDS') == 'ok IDS never answered'
    link.send(ids())
    link.send(fps())
    link.send(ids())
    link.send(tis())
    # every response belongs to a later request: the IDS requests got none
    assert link.names(2) == ['FPS', 'TIS']


def test_a_delayed_service_is_answered_late_and_others_meanwhile(rig) -> None:
    control, link = rig
    assert control.execute(f'delay ids {DELAY_S}') == f'ok IDS answered {DELAY_S:g} s late'
    sent = link.send(ids())
    link.send(fps())
    assert link.response()[0] == 'FPS'
    broadcasts = link.broadcasts
    name, arrived = link.response()
    assert name == 'IDS' and arrived - sent >= DELAY_S  # not before the delay
    assert link.broadcasts > broadcasts  # the bus went on while it waited


def test_clear_restores_every_answer(rig) -> None:
    control, link = rig
    control.execute('mute IDS')
    control.execute('delay FPS 5')
    assert control.execute('clear') == 'ok'
    for request in (ids(), fps(), tis()):
        link.send(request)
    assert link.names(3) == ['IDS', 'FPS', 'TIS']


def test_an_unknown_service_is_refused_with_the_services_it_answers(rig) -> None:
    control, _ = rig
    answer = control.execute('mute yaw_position')
    assert answer.startswith(
        "error mute: unknown request 'yaw_position'; known: DDS, DUS, FPS, IDS, NIS, TIS, "
        'charging_control, cover_control'), answer
    assert 'stop_actuators' in answer and 'yaw_velocity_setpoint' in answer, answer


def test_the_sim_handle_logs_a_muted_service_as_received(tmp_path) -> None:
    handle = make_handle(driver_of_package('canaero_turret_driver'), tmp_path)
    handle.start()
    link = Slcan(handle.server.port_name)
    try:
        handle.mute('IDS')
        link.send(ids())
        link.send(fps())
        assert link.response()[0] == 'FPS'
        assert handle.requests()[-2:] == ['service IDS', 'service FPS']
        handle.clear()
        link.send(ids())
        assert link.response()[0] == 'IDS'
    finally:
        link.close()
        handle.stop()
