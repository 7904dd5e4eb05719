"""TcpStream over loopback and SerialStream over a real pseudo-terminal."""

from __future__ import annotations

import contextlib
import os
import socket
import threading
import tty

import pytest

from gimbal_driver_common.transport import (
    LinkClosed,
    SerialStream,
    TcpStream,
    TransportError,
    read_exactly,
    write_all,
)


class EchoServer:
    """A loopback TCP echo server that can vanish and come back on the same port."""

    def __init__(self) -> None:
        self.listener = socket.create_server(('127.0.0.1', 0))
        self.port = self.listener.getsockname()[1]
        self.clients: list[socket.socket] = []
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while True:
            try:
                client, _ = self.listener.accept()
            except OSError:
                return
            self.clients.append(client)
            threading.Thread(target=self._echo, args=(client,), daemon=True).start()

    @staticmethod
    def _echo(client: socket.socket) -> None:
        try:
            while data := client.recv(4096):
                client.sendall(data)
        except OSError:
            pass

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.listener.shutdown(socket.SHUT_RDWR)  # wakes the accept() thread
        self.listener.close()
        for client in self.clients:
            with contextlib.suppress(OSError):
                client.shutdown(socket.SHUT_RDWR)
            client.close()


def test_tcp_round_trip_and_timeout() -> None:
    server = EchoServer()
    try:
        with TcpStream('127.0.0.1', server.port) as stream:
            assert stream.is_open
            stream.write(b'hello')
            assert read_exactly(stream, 5, 2.0) == b'hello'
            assert stream.read(10, 0.05) == b''  # silence is not an error
        assert not stream.is_open
    finally:
        server.close()


def test_tcp_connect_refused_is_a_clear_error() -> None:
    port = socket.create_server(('127.0.0.1', 0))
    free = port.getsockname()[1]
    port.close()
    stream = TcpStream('127.0.0.1', free, connect_timeout=0.5)
    with pytest.raises(TransportError, match=f'127.0.0.1:{free}'):
        stream.open()


def test_tcp_peer_disappears_and_comes_back() -> None:
    server = EchoServer()
    port = server.port
    stream = TcpStream('127.0.0.1', port)
    stream.open()
    stream.write(b'x')
    assert read_exactly(stream, 1, 2.0) == b'x'
    server.close()
    with pytest.raises(LinkClosed):
        for _ in range(50):
            stream.read(10, 0.1)
    stream.close()
    # The device comes back on the same port: a new open works.
    listener = socket.create_server(('127.0.0.1', port))
    try:
        stream.open()
        client, _ = listener.accept()
        client.sendall(b'back')
        assert read_exactly(stream, 4, 2.0) == b'back'
        client.close()
    finally:
        stream.close()
        listener.close()


def test_write_on_closed_stream_raises_link_closed() -> None:
    with pytest.raises(LinkClosed):
        TcpStream('127.0.0.1', 1).write(b'x')


def _raw_pty() -> tuple[int, str, int]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    return master, os.ttyname(slave), slave


def test_serial_over_pty_round_trip() -> None:
    master, name, slave = _raw_pty()
    try:
        with SerialStream(name, 115200) as stream:
            stream.write(b'\x00\xffping')
            assert os.read(master, 100) == b'\x00\xffping'
            os.write(master, b'pong\x06')
            assert read_exactly(stream, 5, 2.0) == b'pong\x06'
            assert stream.read(10, 0.05) == b''
    finally:
        os.close(master)
        os.close(slave)


def slow_os_write(monkeypatch: pytest.MonkeyPatch, seconds: float) -> None:
    """Every os.write takes ``seconds`` first: the writing thread descheduled under load."""
    import gimbal_driver_common.transport as transport

    write = os.write

    def slow(fd: int, data: bytes) -> int:
        threading.Event().wait(seconds)
        return write(fd, data)

    monkeypatch.setattr(transport.os, 'write', slow)


def test_a_write_that_went_out_is_not_a_timeout_however_long_it_took(monkeypatch) -> None:
    """pyserial's timed write raised SerialTimeoutException after writing every byte when
    the timeout had expired meanwhile; write_all counts only time without room."""
    master, name, slave = _raw_pty()
    try:
        with SerialStream(name, 115200) as stream:
            stream.write_timeout = 0.05
            slow_os_write(monkeypatch, 0.2)
            stream.write(b'ping')
            assert os.read(master, 100) == b'ping'
    finally:
        os.close(master)
        os.close(slave)


def test_write_all_times_out_only_while_the_reader_stalls() -> None:
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    try:
        with pytest.raises(TimeoutError, match=r'no room to write for 0\.1 s'):
            write_all(write_end, b'x' * (1 << 20), 0.1)  # more than a pipe holds
        drained = threading.Thread(target=lambda: os.read(read_end, 1 << 20))
        drained.start()
        drained.join()
        write_all(write_end, b'y' * 1000, 0.1)  # room again: no timeout
    finally:
        os.close(read_end)
        os.close(write_end)


def test_serial_missing_port_is_a_clear_error() -> None:
    with pytest.raises(TransportError, match='/dev/does-not-exist'):
        SerialStream('/dev/does-not-exist').open()


def test_serial_port_vanishing_raises_link_closed() -> None:
    master, name, slave = _raw_pty()
    stream = SerialStream(name)
    stream.open()
    os.close(master)
    os.close(slave)
    with pytest.raises(LinkClosed):
        for _ in range(20):
            stream.read(10, 0.05)
    stream.close()


def test_tcp_close_from_another_thread_raises_link_closed() -> None:
    server = EchoServer()
    try:
        stream = TcpStream('127.0.0.1', server.port)
        stream.open()
        sock = stream._sock  # the socket a reader thread still holds
        sock.close()
        with pytest.raises(LinkClosed):
            stream.read(10, 0.1)
    finally:
        stream.close()
        server.close()


def test_tcp_write_to_a_device_that_stops_reading_fails_after_write_timeout() -> None:
    listener = socket.create_server(('127.0.0.1', 0))
    accepted: list[socket.socket] = []
    threading.Thread(target=lambda: accepted.append(listener.accept()[0]), daemon=True).start()
    stream = TcpStream('127.0.0.1', listener.getsockname()[1], write_timeout=0.2)
    try:
        stream.open()
        chunk = b'x' * 65536
        with pytest.raises(LinkClosed, match='send stalled'):
            for _ in range(10_000):  # the peer never reads: the buffers fill, then it stalls
                stream.write(chunk)
    finally:
        stream.close()
        for sock in [*accepted, listener]:
            sock.close()


def test_tcp_large_write_waits_for_room_and_arrives_whole() -> None:
    server = EchoServer()
    stream = TcpStream('127.0.0.1', server.port)
    try:
        stream.open()
        payload = bytes(range(256)) * 8192  # 2 MiB: more than the socket buffers hold
        received = bytearray()
        reader = threading.Thread(target=lambda: received.extend(
            read_exactly(stream, len(payload), 10.0)), daemon=True)
        reader.start()
        stream.write(payload)
        reader.join(15.0)
        assert bytes(received) == payload
    finally:
        stream.close()
        server.close()
