"""TcpSimServer and PtySimServer: sessions, streaming, and every fault injection."""

from __future__ import annotations

import pytest

from gimbal_driver_common.sim_server import PtySimServer, TcpSimServer
from gimbal_driver_common.transport import LinkClosed, SerialStream, TcpStream, read_exactly
from gimbal_driver_testing import wait_for


class UpperSession:
    """Replies with the upper-cased input; streams b'.' when ``stream`` is set."""

    stream = False

    def on_bytes(self, data: bytes) -> bytes:
        return data.upper()

    def poll(self) -> bytes:
        return b'.' if UpperSession.stream else b''


@pytest.fixture
def tcp_server():
    server = TcpSimServer(UpperSession).start()
    yield server
    server.stop()


def test_tcp_sim_refuses_non_loopback() -> None:
    with pytest.raises(ValueError, match='loopback'):
        TcpSimServer(UpperSession, host='0.0.0.0')


def test_tcp_session_replies_and_garbage_injection(tcp_server: TcpSimServer) -> None:
    with TcpStream(*tcp_server.address) as stream:
        stream.write(b'abc')
        assert read_exactly(stream, 3, 2.0) == b'ABC'
        tcp_server.inject(b'\xde\xad')
        assert read_exactly(stream, 2, 2.0) == b'\xde\xad'


def test_tcp_silence_and_drop_link(tcp_server: TcpSimServer) -> None:
    stream = TcpStream(*tcp_server.address)
    stream.open()
    tcp_server.set_silent(True)
    stream.write(b'abc')
    assert stream.read(10, 0.2) == b''
    tcp_server.set_silent(False)
    wait_for(lambda: tcp_server.client_count == 1, 2.0, 'the client to be accepted')
    tcp_server.drop_link()
    with pytest.raises(LinkClosed):
        for _ in range(40):
            stream.read(10, 0.05)
    stream.close()
    stream.open()  # the simulator accepts a reconnect
    stream.write(b'x')
    assert read_exactly(stream, 1, 2.0) == b'X'
    assert tcp_server.connections == 2
    stream.close()


def test_tcp_streaming_poll(tcp_server: TcpSimServer) -> None:
    UpperSession.stream = True
    try:
        with TcpStream(*tcp_server.address) as stream:
            assert read_exactly(stream, 3, 2.0) == b'...'
    finally:
        UpperSession.stream = False


def test_pty_session_drop_and_recreate() -> None:
    server = PtySimServer(UpperSession).start()
    try:
        stream = SerialStream(server.port_name)
        stream.open()
        stream.write(b'hi')
        assert read_exactly(stream, 2, 2.0) == b'HI'
        server.inject(b'\x00')
        assert read_exactly(stream, 1, 2.0) == b'\x00'
        server.drop_link(offline_for=0.2)
        with pytest.raises(LinkClosed):
            for _ in range(40):
                stream.write(b'x')
                stream.read(10, 0.05)
        stream.close()
        wait_for(lambda: server.connections == 2, 3.0, 'the pty to come back')
        stream.open()  # same path, new pty
        stream.write(b'ok')
        assert read_exactly(stream, 2, 2.0) == b'OK'
        stream.close()
    finally:
        server.stop()


def test_receive_hook_runs_after_each_handled_request(tcp_server: TcpSimServer) -> None:
    calls: list[int] = []
    tcp_server.add_receive_hook(lambda: calls.append(1))
    with TcpStream(*tcp_server.address) as stream:
        stream.write(b'a')
        assert read_exactly(stream, 1, 2.0) == b'A'
        wait_for(lambda: calls, 2.0, 'the receive hook')
        tcp_server.set_silent(True)  # a silent device handles nothing
        stream.write(b'b')
        assert stream.read(10, 0.2) == b''
    assert len(calls) == 1
