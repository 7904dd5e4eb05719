"""The shared request faults on the Capture simulator, over TCP and the pty: a muted command
is never answered and a delayed one is answered late (a data packet and an ACK-only reply
alike), while the other commands are answered at once; ``clear`` restores."""

from __future__ import annotations

import time

import pytest

from capture_driver.protocol import BY_OPCODE, COMMANDS, Frame, ReplyByte, ReplyCode, StreamDecoder
from capture_driver.sim import CaptureSimulator, PedestalModel
from gimbal_driver_common.registry import driver_of_package
from gimbal_driver_common.sim_handle import make_handle
from gimbal_driver_common.transport import ByteStream, SerialStream, TcpStream
from gimbal_driver_testing import wait_for

DELAY_S = 0.4


class Link:
    """The host side of one link: requests out, replies (data packets by command name, ACK
    and NACK bytes) in, each stamped with the time it arrived."""

    def __init__(self, stream: ByteStream, greeting: bool) -> None:
        self.stream = stream
        self.stream.open()
        self.decoder = StreamDecoder()
        self.pending: list[Frame | ReplyByte] = []
        if greeting:  # TCP: the controller greets with COM_Connect
            assert self.reply() == 'COM_Connect'
        self.send('COM_Connect')
        assert self.reply() == 'ACK'

    def send(self, name: str, axis: int | None = None, value: object = None) -> float:
        sent = time.monotonic()  # before the write: the device may act before it returns
        self.stream.write(COMMANDS[name].encode(axis, value))
        return sent

    def reply(self, timeout: float = 10.0) -> str:
        """The next reply: a data packet's command name, ``ACK`` or ``NACK 0xNN``."""
        return self.stamped_reply(timeout)[0]

    def stamped_reply(self, timeout: float = 10.0) -> tuple[str, float]:
        def item() -> Frame | ReplyByte | None:
            if not self.pending:
                self.pending += [i for i in self.decoder.feed(self.stream.read(4096, 0.05))
                                 if isinstance(i, Frame | ReplyByte)]
            return self.pending.pop(0) if self.pending else None

        got = wait_for(item, timeout, 'a reply')
        arrived = time.monotonic()
        if isinstance(got, Frame):
            return BY_OPCODE[got.opcode].name, arrived
        return ('ACK' if got.code == ReplyCode.ACK else f'NACK 0x{int(got.code):02X}'), arrived

    def close(self) -> None:
        self.stream.close()


@pytest.fixture(scope='module')
def simulator():
    with CaptureSimulator(PedestalModel(), tcp_port=0, pty=True) as sim:
        yield sim


@pytest.fixture(params=['tcp', 'pty'])
def rig(simulator, request):
    simulator.control('clear')
    if request.param == 'tcp':
        link = Link(TcpStream('127.0.0.1', simulator.tcp.port), greeting=True)
    else:
        link = Link(SerialStream(simulator.pty.port_name), greeting=False)
    yield simulator, link
    link.close()
    simulator.control('clear')


def count(simulator: CaptureSimulator, name: str) -> int:
    answer = simulator.control(f'count {name}')
    assert answer.startswith('ok '), answer
    return int(answer[3:])


def test_a_muted_command_is_never_answered_while_others_are(rig) -> None:
    simulator, link = rig
    assert simulator.control('mute IMU_GetRoll') == 'ok IMU_GetRoll never answered'
    before = count(simulator, 'IMU_GetRoll')
    link.send('IMU_GetRoll')
    link.send('MOT_GetLoadPosition', 1)
    link.send('MOT_SetSpeed', 1, 5.0)
    link.send('IMU_GetRoll')
    link.send('MOT_GetLoadPosition', 2)
    # every reply belongs to a later command: the two IMU_GetRoll got none
    assert [link.reply() for _ in range(3)] == ['MOT_GetLoadPosition', 'ACK',
                                                'MOT_GetLoadPosition']
    assert count(simulator, 'IMU_GetRoll') == before + 2  # received as the device saw them


def test_a_delayed_data_reply_comes_late_and_others_meanwhile(rig) -> None:
    simulator, link = rig
    assert simulator.control(f'delay IMU_GetRoll {DELAY_S}').startswith('ok ')
    sent = link.send('IMU_GetRoll')
    link.send('MOT_GetLoadPosition', 1)
    link.send('MOT_SetSpeed', 1, 5.0)
    assert link.reply() == 'MOT_GetLoadPosition'
    assert link.reply() == 'ACK'
    name, arrived = link.stamped_reply()
    assert name == 'IMU_GetRoll'
    assert arrived - sent >= DELAY_S  # not before the delay


def test_a_delayed_ack_only_reply_still_goes_out_late(rig) -> None:
    simulator, link = rig
    assert simulator.control(f'delay mot_setspeed {DELAY_S}') == \
        f'ok MOT_SetSpeed answered {DELAY_S:g} s late'
    sent = link.send('MOT_SetSpeed', 1, 5.0)
    link.send('MOT_GetLoadPosition', 1)
    assert link.reply() == 'MOT_GetLoadPosition'
    name, arrived = link.stamped_reply()
    assert name == 'ACK' and arrived - sent >= DELAY_S
    with simulator.model.lock:  # executed on arrival: only its answer waited
        assert simulator.model.axes[1].speed == 5.0


def test_clear_restores_every_answer(rig) -> None:
    simulator, link = rig
    simulator.control('mute IMU_GetRoll')
    simulator.control('delay MOT_SetSpeed 5')
    assert simulator.control('clear') == 'ok'
    link.send('IMU_GetRoll')
    link.send('MOT_SetSpeed', 1, 5.0)
    link.send('MOT_GetLoadPosition', 1)
    assert [link.reply() for _ in range(3)] == ['IMU_GetRoll', 'ACK', 'MOT_GetLoadPosition']


def test_an_unknown_command_name_is_refused_with_the_table(simulator) -> None:
    answer = simulator.control('mute IMU_GetWeather')
    assert answer.startswith("error mute: unknown request 'IMU_GetWeather'; known: ")
    assert 'IMU_GetRoll' in answer and 'MOT_GetLoadPosition' in answer


def test_the_sim_handle_logs_a_muted_command_as_received(tmp_path) -> None:
    handle = make_handle(driver_of_package('capture_driver'), tmp_path)
    handle.start()
    link = Link(TcpStream('127.0.0.1', handle.port), greeting=True)
    try:
        handle.mute('IMU_GetRoll')
        link.send('IMU_GetRoll')
        link.send('MOT_GetLoadPosition', 1)
        assert link.reply() == 'MOT_GetLoadPosition'
        assert handle.requests()[-2:] == ['IMU_GetRoll', 'MOT_GetLoadPosition']
        handle.clear()
        link.send('IMU_GetRoll')
        assert link.reply() == 'IMU_GetRoll'
    finally:
        link.close()
        handle.stop()


def test_an_ignored_setter_is_acked_and_not_executed(rig) -> None:
    simulator, link = rig
    answer = simulator.control('ignore MOT_SetSpeed 30')
    assert answer == 'ok MOT_SetSpeed answered but not acted on for 30 s', answer
    before = count(simulator, 'MOT_SetSpeed')
    with simulator.model.lock:
        speed = simulator.model.axes[1].speed or 0.0
    link.send('MOT_SetSpeed', 1, speed + 7.0)
    link.send('MOT_GetLoadPosition', 1)
    assert [link.reply() for _ in range(2)] == ['ACK', 'MOT_GetLoadPosition']
    assert count(simulator, 'MOT_SetSpeed') == before + 1  # received
    with simulator.model.lock:
        assert simulator.model.axes[1].speed == speed  # not executed
    simulator.control('ignore MOT_SetSpeed 0')
    link.send('MOT_SetSpeed', 1, speed + 7.0)
    assert link.reply() == 'ACK'
    with simulator.model.lock:
        assert simulator.model.axes[1].speed == speed + 7.0
