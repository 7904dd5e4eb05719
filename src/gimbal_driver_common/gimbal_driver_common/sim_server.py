"""Serve a simulated device over TCP (127.0.0.1) or a pseudo-terminal.

A simulator provides a *session factory*; each connection gets a session
object that turns received bytes into reply bytes. The servers here own the
sockets, threads and fault injection (dropped link, garbage, silence), so
every device simulator gets the same, tested link behaviour.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import socket
import tempfile
import threading
import time
import tty
from collections.abc import Callable
from typing import Protocol, runtime_checkable

LOG = logging.getLogger(__name__)

LOOPBACK = '127.0.0.1'


@runtime_checkable
class SimSession(Protocol):
    """What a device simulator implements for one connection."""

    def on_bytes(self, data: bytes) -> bytes | list[bytes]:
        """Consume received bytes; return the bytes to send back (may be empty), or
        each reply on its own (a server with ``nagle`` then sends each in its own write)."""


SessionFactory = Callable[[], SimSession]


class _Faults:
    """Fault switches shared by a server's connections."""

    def __init__(self) -> None:
        self.silent = False
        self.pending_garbage: list[bytes] = []
        self.lock = threading.Lock()

    def take_garbage(self) -> bytes:
        with self.lock:
            data = b''.join(self.pending_garbage)
            self.pending_garbage.clear()
        return data


def _session_poll(session: SimSession) -> bytes:
    poll = getattr(session, 'poll', None)
    return poll() if poll is not None else b''


class _SimServerBase:
    """Threads and fault injection common to the TCP and pty servers."""

    #: send each reply of a session in its own write (see :class:`TcpSimServer` ``nagle``)
    separate_sends = False

    def __init__(self, session_factory: SessionFactory, poll_interval: float = 0.005) -> None:
        self._session_factory = session_factory
        self.poll_interval = poll_interval
        self._faults = _Faults()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.connections = 0  # connections accepted so far (tests watch reconnects)
        self._receive_hooks: list[Callable[[], None]] = []

    def add_receive_hook(self, hook: Callable[[], None]) -> None:
        """Call ``hook()`` after a session has handled received bytes (instrumentation,
        e.g. timing when a command reached the device model)."""
        self._receive_hooks.append(hook)

    def inject(self, data: bytes) -> None:
        """Send ``data`` (garbage, a corrupted frame, ...) to the connected client(s)."""
        with self._faults.lock:
            self._faults.pending_garbage.append(bytes(data))

    def set_silent(self, silent: bool) -> None:
        """Stop (or resume) answering and streaming, keeping the link up."""
        self._faults.silent = silent

    @property
    def silent(self) -> bool:
        return self._faults.silent

    def _spawn(self, target: Callable[..., None], *args: object, name: str) -> None:
        thread = threading.Thread(target=target, args=args, name=name, daemon=True)
        thread.start()
        self._threads.append(thread)

    def _serve_fd_loop(
        self,
        session: SimSession,
        wait_readable: Callable[[float], bool],
        receive: Callable[[], bytes],
        send: Callable[[bytes], None],
        alive: Callable[[], bool],
    ) -> None:
        """Pump bytes between one link and one session until the link ends."""
        next_poll = time.monotonic()
        while not self._stop.is_set() and alive():
            timeout = max(0.0, next_poll - time.monotonic())
            try:
                readable = wait_readable(timeout)
                out = b''
                replies: list[bytes] = []
                if readable:
                    data = receive()
                    if not data:
                        return
                    if not self._faults.silent:
                        answer = session.on_bytes(data)
                        replies = [answer] if isinstance(answer, bytes | bytearray) else answer
                        for hook in self._receive_hooks:
                            hook()
                now = time.monotonic()
                if now >= next_poll:
                    next_poll = now + self.poll_interval
                    streamed = _session_poll(session)
                    if not self._faults.silent:
                        out += streamed
                if self.separate_sends:
                    for reply in [self._faults.take_garbage(), *replies, out]:
                        if reply:
                            send(reply)
                    continue
                out = self._faults.take_garbage() + b''.join(replies) + out
                if out:
                    send(out)
            except OSError:
                return


class TcpSimServer(_SimServerBase):
    """A TCP server on loopback; one session per accepted client."""

    def __init__(
        self,
        session_factory: SessionFactory,
        host: str = LOOPBACK,
        port: int = 0,
        poll_interval: float = 0.005,
        nagle: bool = False,
    ) -> None:
        """``nagle``: behave like an embedded TCP stack that leaves Nagle's algorithm on
        and writes each reply on its own (the default sets TCP_NODELAY): a reply after
        the first of a burst then waits for the ACK of the one before, which a client
        that delays its ACKs holds back for up to 40 ms."""
        super().__init__(session_factory, poll_interval)
        self.nagle = nagle
        self.separate_sends = nagle
        if host not in (LOOPBACK, 'localhost', '::1'):
            raise ValueError('simulators bind to loopback only (127.0.0.1)')
        self.host = host
        self._requested_port = port
        self._listener: socket.socket | None = None
        self._clients: set[socket.socket] = set()
        self._clients_lock = threading.Lock()
        self._refuse_until = 0.0

    @property
    def port(self) -> int:
        if self._listener is None:
            raise RuntimeError('server not started')
        return self._listener.getsockname()[1]

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    def start(self) -> TcpSimServer:
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind((self.host, self._requested_port))
        listener.listen(4)
        listener.settimeout(0.1)
        self._listener = listener
        self._spawn(self._accept_loop, name=f'sim-accept-{self.port}')
        return self

    def stop(self) -> None:
        self._stop.set()
        self.drop_link()
        if self._listener is not None:
            self._listener.close()
        for thread in self._threads:
            thread.join(timeout=2.0)

    def drop_link(self, refuse_for: float = 0.0) -> None:
        """Cut every client (as a pulled cable does); refuse new ones for ``refuse_for`` s."""
        self._refuse_until = time.monotonic() + refuse_for
        with self._clients_lock:
            clients = list(self._clients)
            self._clients.clear()
        for client in clients:
            with contextlib.suppress(OSError):
                client.shutdown(socket.SHUT_RDWR)
            client.close()

    @property
    def client_count(self) -> int:
        with self._clients_lock:
            return len(self._clients)

    def _accept_loop(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except (TimeoutError, BlockingIOError):
                continue
            except OSError:
                return
            if time.monotonic() < self._refuse_until:
                client.close()
                continue
            if not self.nagle:
                client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._clients_lock:
                self._clients.add(client)
            self.connections += 1
            self._spawn(self._serve_client, client, name='sim-client')

    def _serve_client(self, client: socket.socket) -> None:
        session = self._session_factory()

        def wait_readable(timeout: float) -> bool:
            return bool(select.select([client], [], [], timeout)[0])

        def alive() -> bool:
            with self._clients_lock:
                return client in self._clients

        try:
            self._serve_fd_loop(
                session, wait_readable, lambda: client.recv(65536), client.sendall, alive
            )
        finally:
            with self._clients_lock:
                self._clients.discard(client)
            client.close()
            closed = getattr(session, 'on_disconnect', None)
            if closed is not None:
                closed()


class PtySimServer(_SimServerBase):
    """A pseudo-terminal whose slave side a driver opens as a serial port.

    ``port_name`` is a stable symlink: after :meth:`drop_link` (which destroys
    the pty, like unplugging a USB adapter) a new pty is made behind the same
    path so a reconnecting driver finds the device again.
    """

    def __init__(
        self,
        session_factory: SessionFactory,
        link_path: str | None = None,
        poll_interval: float = 0.005,
    ) -> None:
        super().__init__(session_factory, poll_interval)
        self._tmpdir: tempfile.TemporaryDirectory[str] | None = None
        if link_path is None:
            self._tmpdir = tempfile.TemporaryDirectory(prefix='gimbal-sim-')
            link_path = os.path.join(self._tmpdir.name, 'tty')
        self.link_path = link_path
        self._master = -1
        self._slave = -1
        self._generation = 0
        self._lock = threading.Lock()
        self._offline_until = 0.0

    @property
    def port_name(self) -> str:
        return self.link_path

    def start(self) -> PtySimServer:
        self._open_pty()
        self._spawn(self._run, name='sim-pty')
        return self

    def stop(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._close_pty()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.link_path)
        if self._tmpdir is not None:
            self._tmpdir.cleanup()

    def drop_link(self, offline_for: float = 0.0) -> None:
        """Destroy the pty (the driver's port read fails); recreate it after ``offline_for`` s."""
        with self._lock:
            self._offline_until = time.monotonic() + offline_for
            self._generation += 1
            self._close_pty_locked()
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.link_path)

    def _open_pty(self) -> None:
        with self._lock:
            master, slave = os.openpty()
            tty.setraw(slave)  # no echo or line editing before the driver configures it
            tty.setraw(master)
            self._master, self._slave = master, slave
            tmp_link = f'{self.link_path}.{os.getpid()}.tmp'
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp_link)
            os.symlink(os.ttyname(slave), tmp_link)
            os.replace(tmp_link, self.link_path)
            self.connections += 1

    def _close_pty_locked(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1

    def _close_pty(self) -> None:
        with self._lock:
            self._close_pty_locked()

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                master, generation = self._master, self._generation
            if master < 0:
                if time.monotonic() >= self._offline_until:
                    self._open_pty()
                else:
                    time.sleep(0.02)
                continue
            session = self._session_factory()

            def alive(gen: int = generation) -> bool:
                return self._generation == gen

            def wait_readable(timeout: float, fd: int = master) -> bool:
                return bool(select.select([fd], [], [], timeout)[0])

            def receive(fd: int = master) -> bytes:
                return os.read(fd, 65536)

            def send(data: bytes, fd: int = master) -> None:
                view = memoryview(data)
                while view:
                    written = os.write(fd, view)
                    view = view[written:]

            self._serve_fd_loop(session, wait_readable, receive, send, alive)
            closed = getattr(session, 'on_disconnect', None)
            if closed is not None:
                closed()
            if alive():
                # The loop ended on an I/O error with the pty still ours: rebuild it.
                self.drop_link()
