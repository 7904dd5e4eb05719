"""The shared request faults on the virtual gimbal's simulator, over its TCP link: a muted
request verb is never answered and a delayed one is answered late, while the other
requests are answered at once; ``clear`` restores. Set through the in-process handle
(:class:`~gimbal_driver_common.sim_handle.SimHandle`) and the control verbs."""

from __future__ import annotations

import time

import pytest

from gimbal_driver_common.registry import driver_of_package
from gimbal_driver_common.sim_handle import make_handle
from gimbal_driver_common.transport import TcpStream
from gimbal_driver_testing import wait_for

DELAY_S = 0.4


class Lines:
    """One TCP connection to the simulator: request lines out, reply lines in, each reply
    stamped with the time it arrived."""

    def __init__(self, port: int) -> None:
        self.stream = TcpStream('127.0.0.1', port)
        self.stream.open()
        self.buffer = b''

    def send(self, line: str) -> float:
        sent = time.monotonic()  # before the write: the device may act before it returns
        self.stream.write(line.encode() + b'\n')
        return sent

    def reply(self, timeout: float = 10.0) -> tuple[str, float]:
        """The next reply line and when it arrived (TimeoutError if none within timeout)."""
        def line() -> bytes | None:
            if b'\n' not in self.buffer:
                self.buffer += self.stream.read(4096, 0.05)
            return self.buffer if b'\n' in self.buffer else None

        wait_for(line, timeout, 'a reply line')
        arrived = time.monotonic()
        head, self.buffer = self.buffer.split(b'\n', 1)
        return head.decode(), arrived

    def close(self) -> None:
        self.stream.close()


@pytest.fixture
def sim(tmp_path):
    handle = make_handle(driver_of_package('virtual_gimbal_driver'), tmp_path)
    handle.start()
    link = Lines(handle.port)
    yield handle, link
    link.close()
    handle.stop()


def test_a_muted_request_is_never_answered_nor_acted_on_but_logged(sim) -> None:
    handle, link = sim
    handle.control('fault overtemp')
    handle.mute('RESET')
    link.send('RESET')
    link.send('GET')
    link.send('ID')
    position, _ = link.reply()
    # the answers that follow belong to the later requests: RESET got none
    assert position.startswith('POS ') and position.split()[-1] == '1'  # fault still set
    assert link.reply()[0].startswith('ID ')
    assert handle.requests()[-3:] == ['RESET', 'GET', 'ID']  # received, as the device saw it
    assert handle.controls().request_faults.muted('RESET')


def test_a_delayed_request_is_answered_late_and_others_meanwhile(sim) -> None:
    handle, link = sim
    handle.delay('GET', DELAY_S)
    sent = link.send('GET')
    link.send('ID')
    link.send('MOVE pan 0.1 0.5')
    assert link.reply()[0].startswith('ID ')  # answered while GET waits
    assert link.reply()[0] == 'OK'
    position, arrived = link.reply()
    assert position.startswith('POS ')
    assert arrived - sent >= DELAY_S  # not before the delay


def test_clear_restores_every_answer(sim) -> None:
    handle, link = sim
    handle.mute('reset')  # the verb's case does not matter
    handle.delay('GET', 5.0)
    handle.clear()
    for request in ('RESET', 'GET', 'ID'):
        link.send(request)
    replies = [link.reply()[0] for _ in range(3)]
    assert replies[0] == 'OK' and replies[1].startswith('POS ') and replies[2].startswith('ID ')
    state = handle.controls().execute('state')
    assert '"muted": []' in state and '"delayed": {}' in state


def test_the_console_names_the_request_verbs(sim) -> None:
    handle, _ = sim
    answer = handle.controls().execute('mute PING')
    assert answer == ("error mute: unknown request 'PING'; known: GET, HOME, ID, JOG, MOVE, "
                      'RESET, STOP')
    assert '(requests: GET, HOME, ID, JOG, MOVE, RESET, STOP)' in \
        handle.controls().execute('help')


def test_an_ignored_stop_is_answered_ok_and_not_acted_on_until_its_time_ends(sim) -> None:
    handle, link = sim
    link.send('JOG pan 0.3')
    assert link.reply()[0] == 'OK'
    wait_for(lambda: handle.moving('pan'), 10.0, 'pan jogging')
    handle.ignore('STOP', 0.5)
    link.send('STOP pan')
    assert link.reply()[0] == 'OK'  # answered as always
    assert handle.moving('pan')  # and not acted on
    assert handle.requests()[-1] == 'STOP pan'  # received
    wait_for(lambda: not handle.controls().request_faults.ignored('STOP'), 10.0,
             'the ignore to end')
    link.send('STOP pan')
    assert link.reply()[0] == 'OK'
    wait_for(lambda: not handle.moving('pan'), 10.0, 'pan at rest')


def test_a_delay_beyond_the_request_timeout_still_answers(sim) -> None:
    handle, link = sim
    handle.delay('STOP', 1.5)  # beyond the client's request_timeout
    sent = link.send('STOP')
    reply, arrived = link.reply()
    assert reply == 'OK' and arrived - sent >= 1.5
