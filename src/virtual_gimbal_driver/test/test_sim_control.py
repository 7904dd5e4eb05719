"""The shared simulator control protocol (sim_control), tested once on the virtual gimbal:
every shared verb through the TCP console, acting on the real TCP link; the ready line,
the stdin console and ``quit`` of the installed ``virtual_gimbal_sim`` process."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from gimbal_driver_common.sim_control import (
    ControlClient,
    ControlServer,
    SimControl,
    decode_state,
    parse_ready_line,
    read_ready_line,
    ready_line,
)
from gimbal_driver_common.transport import LinkClosed, TcpStream, read_exactly
from gimbal_driver_testing import wait_for
from virtual_gimbal_driver.sim import make_control, make_server


@pytest.fixture
def rig():
    server, device = make_server(0)
    control = make_control(server, device)
    console = ControlServer(control).start()
    client = ControlClient(console.port)
    yield server, device, client
    client.close()
    console.stop()
    server.stop()


def request(port: int, line: str, timeout: float = 5.0) -> str:
    """One line-protocol request on a fresh TCP connection; the raw reply line ('' if the
    device stays silent for ``timeout``)."""
    with TcpStream('127.0.0.1', port) as stream:
        stream.write(line.encode() + b'\n')
        reply, deadline = b'', time.monotonic() + timeout
        while not reply.endswith(b'\n') and time.monotonic() < deadline:
            reply += stream.read(4096, max(deadline - time.monotonic(), 0.01))
    return reply.decode().strip()


def test_state_is_json_of_the_axes(rig) -> None:
    server, _, client = rig
    assert request(server.port, 'MOVE pan 0.05 1.0') == 'OK'

    def at_rest() -> dict | None:
        state = client.state()
        return None if state['axes']['pan']['moving'] else state

    state = wait_for(at_rest, 10, 'the pan move to end')
    assert state['axes']['pan']['position'] == 0.05
    assert set(state['axes']['tilt']) == {'position', 'velocity', 'target', 'mode', 'moving'}


def test_drop_cuts_the_link_and_refuses_for_the_given_time(rig) -> None:
    server, _, client = rig
    stream = TcpStream('127.0.0.1', server.port)
    stream.open()
    wait_for(lambda: server.client_count == 1, 5, 'the client to be accepted')
    assert client.command('drop 0') == 'ok'
    with pytest.raises(LinkClosed):
        for _ in range(100):
            stream.read(10, 0.05)
    stream.close()
    assert request(server.port, 'ID').startswith('ID virtual-gimbal')  # back at once


def test_silence_keeps_the_link_and_stops_answers(rig) -> None:
    server, _, client = rig
    assert client.command('silence on') == 'ok'
    assert request(server.port, 'ID', timeout=0.3) == ''
    assert client.command('silence off') == 'ok'
    assert request(server.port, 'ID').startswith('ID')


def test_garbage_sends_bytes_on_the_link(rig) -> None:
    server, _, client = rig
    with TcpStream('127.0.0.1', server.port) as stream:
        wait_for(lambda: server.client_count == 1, 5, 'the client to be accepted')
        assert client.command('garbage hex de ad') == 'ok 2 bytes'
        assert read_exactly(stream, 2, 5.0) == b'\xde\xad'
        assert client.command('garbage 5') == 'ok 5 bytes'
        assert len(read_exactly(stream, 5, 5.0)) == 5


def test_nack_every_request_or_the_next_of_one_command(rig) -> None:
    server, _, client = rig
    assert client.command('nack on') == 'ok'
    assert request(server.port, 'ID') == 'ERR ID: injected NACK'
    assert client.command('nack off') == 'ok'
    assert client.command('nack move 1') == 'ok'
    assert request(server.port, 'GET').startswith('POS')  # another command passes
    assert request(server.port, 'MOVE pan 1.0 0') == 'ERR MOVE: injected NACK'
    assert request(server.port, 'MOVE pan 0.0 0') == 'OK'  # only the next one


def test_fault_bits_by_name_or_number_and_clear(rig) -> None:
    server, _, client = rig
    assert client.command('fault overtemp') == 'ok'
    assert request(server.port, 'GET').split()[-1] == '1'
    assert client.command('fault 0x4') == 'ok'
    assert client.state()['faults'] == 5
    assert client.command('nack on') == 'ok'
    assert client.command('silence on') == 'ok'
    assert client.command('clear') == 'ok'  # faults, NACKs and silence all go
    assert request(server.port, 'GET').split()[-1] == '0'


def test_errors_name_the_verb_and_never_raise(rig) -> None:
    _, _, client = rig
    assert client.command('fly away').startswith('error fly: unknown verb')
    assert client.command('fault').startswith('error fault: usage')
    assert client.command('fault nonsense').startswith('error fault: bad arguments')
    assert client.command('silence maybe').startswith('error silence: expected on or off')
    assert client.command('garbage hex zz').startswith('error garbage: not hex')
    assert client.command('drop -1').startswith('error drop:')
    assert client.command('quit').startswith('error quit:')  # in-process: not ours to end
    help_text = client.command('help')
    for verb in ('drop', 'silence', 'garbage', 'nack', 'fault', 'clear', 'state', 'quit'):
        assert verb in help_text


def test_device_without_nack_or_faults_says_why() -> None:
    control = SimControl('plain_sim', lambda: {'axes': {}}, no_nack='UCSP has no NACK')
    assert control.execute('nack on') == 'error nack: not applicable to plain_sim: UCSP has no NACK'
    assert control.execute('fault 1').startswith('error fault: not applicable')
    assert control.execute('drop').startswith('error drop: plain_sim has no byte link')
    control.add_verb('ping', lambda args: 'pong', 'ping')
    assert control.execute('PING') == 'ok pong'
    with pytest.raises(ValueError):
        SimControl('x', dict, verbs={'state': None})  # type: ignore[dict-item]


def test_ready_line_round_trip() -> None:
    text = 'log line\n' + ready_line('capture_sim', port=4949, control_port=5) + '\n{"x": 1}\n'
    assert parse_ready_line(text) == {'ready': 'capture_sim', 'port': 4949, 'control_port': 5}
    assert parse_ready_line(text, 'ucamera_sim') is None
    assert decode_state('ok {"axes": {}}') == {'axes': {}}
    with pytest.raises(RuntimeError):
        decode_state('error state: no')


def test_sim_process_ready_line_stdin_console_and_quit() -> None:
    proc = subprocess.Popen(
        [sys.executable, '-m', 'virtual_gimbal_driver.sim', '--port', '0'],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        ready = read_ready_line(proc.stdout, 'virtual_gimbal_sim')
        assert ready['port'] > 0 and ready['control_port'] > 0
        proc.stdin.write('fault overtemp\n')
        proc.stdin.flush()
        assert proc.stdout.readline().strip() == 'ok'
        with ControlClient(ready['control_port']) as client:
            assert client.state()['faults'] == 1  # the same device behind both consoles
        assert request(ready['port'], 'GET').split()[-1] == '1'
        proc.stdin.write('quit\n')
        proc.stdin.flush()
        assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
