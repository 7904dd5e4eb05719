"""Byte-stream links to devices: TCP client and serial port, with one interface.

A driver's client talks to a :class:`ByteStream` and never to a socket or a
``serial.Serial`` directly, so the same protocol session runs over TCP, RS-232
or a pseudo-terminal. Failures surface as :class:`TransportError` subclasses;
the controller's supervisor (not the client) reconnects.
"""

from __future__ import annotations

import abc
import contextlib
import os
import select
import socket
import threading
import time
from typing import TYPE_CHECKING

from gimbal_driver_common.errors import LinkError

if TYPE_CHECKING:
    import serial

#: Linux's TCP_QUICKACK (None elsewhere): see :meth:`TcpStream.read`.
QUICKACK: int | None = getattr(socket, 'TCP_QUICKACK', None)


class TransportError(LinkError):
    """A link could not be opened, or failed while in use."""


class LinkClosed(TransportError):
    """The peer closed the link or the device disappeared."""


class ByteStream(abc.ABC):
    """A bidirectional byte pipe to one device.

    ``read`` returns ``b''`` on timeout and raises :class:`LinkClosed` when the
    peer is gone, so callers can tell silence from disconnection.
    """

    @property
    @abc.abstractmethod
    def description(self) -> str:
        """Human-readable endpoint, e.g. ``tcp://192.168.10.120:4949``."""

    @property
    @abc.abstractmethod
    def is_open(self) -> bool:
        """True between a successful :meth:`open` and :meth:`close`."""

    @abc.abstractmethod
    def open(self) -> None:
        """Connect; raises :class:`TransportError` with the reason on failure."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the link. Safe to call more than once."""

    @abc.abstractmethod
    def write(self, data: bytes) -> None:
        """Send all of ``data`` or raise :class:`TransportError`."""

    @abc.abstractmethod
    def read(self, max_bytes: int, timeout: float) -> bytes:
        """Return up to ``max_bytes`` bytes, ``b''`` if none arrived within ``timeout``."""

    def __enter__(self) -> ByteStream:
        self.open()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = 'open' if self.is_open else 'closed'
        return f'<{type(self).__name__} {self.description} {state}>'


class TcpStream(ByteStream):
    """TCP client link (e.g. a Capture pedestal on port 4949)."""

    def __init__(self, host: str, port: int, connect_timeout: float = 2.0,
                 write_timeout: float = 2.0) -> None:
        self.host = host
        self.port = int(port)
        self.connect_timeout = connect_timeout
        self.write_timeout = write_timeout
        self._sock: socket.socket | None = None
        self._write_lock = threading.Lock()

    @property
    def description(self) -> str:
        return f'tcp://{self.host}:{self.port}'

    @property
    def is_open(self) -> bool:
        return self._sock is not None

    def open(self) -> None:
        self.close()
        try:
            sock = socket.create_connection((self.host, self.port), self.connect_timeout)
        except OSError as exc:
            raise TransportError(f'cannot connect to {self.description}: {exc}') from exc
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        # Non-blocking for good: read and write wait in poll() themselves (see read).
        sock.setblocking(False)
        self._sock = sock

    def close(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            sock.close()

    def _require(self) -> socket.socket:
        sock = self._sock
        if sock is None:
            raise LinkClosed(f'{self.description} is not open')
        return sock

    def write(self, data: bytes) -> None:
        """Send everything, waiting up to ``write_timeout`` for room in the send buffer
        (a device that stops reading fills it; the link is then reported lost)."""
        sock = self._require()
        with self._write_lock:
            try:
                write_all(sock.fileno(), data, self.write_timeout)
            except TimeoutError:
                raise LinkClosed(f'{self.description}: send stalled for '
                                 f'{self.write_timeout:g} s (the device does not read)') from None
            except OSError as exc:
                raise LinkClosed(f'{self.description}: send failed: {exc}') from exc

    def read(self, max_bytes: int, timeout: float) -> bytes:
        """:func:`read_ready` on the socket, which stays non-blocking: a request/reply
        client reads with a new timeout each time, and ``settimeout`` would cost an ioctl
        on every call."""
        sock = self._require()
        try:
            data = read_ready(sock.fileno(), max_bytes, max(timeout, 0.0))
        except (OSError, ValueError) as exc:
            # A socket closed by another thread: its fileno is -1 (ValueError from poll's
            # register) or the read fails with EBADF.
            if self._sock is None:
                raise LinkClosed(f'{self.description} was closed') from exc
            raise LinkClosed(f'{self.description}: receive failed: {exc}') from exc
        if data is None:
            return b''
        if not data:
            raise LinkClosed(f'{self.description}: peer closed the connection')
        if QUICKACK is not None:
            # A device that leaves Nagle's algorithm on holds each reply after the first
            # of a batch until its previous segment is ACKed, and Linux delays that ACK
            # by up to 40 ms while this side has nothing to send (the Capture poll fell to
            # 17-22 Hz of 50 against such a controller). TCP_QUICKACK is not sticky: set
            # after every read, it sends the pending ACK now. One setsockopt per read
            # (about 1 us); the batched poll then measured the same rate as with
            # TCP_NODELAY on both ends (bench: capture nagle_poll_rate).
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, QUICKACK, 1)
        return data


def wait_ready(fd: int, event: int, timeout: float | None) -> bool:
    """True when descriptor ``fd`` is ready for ``event`` (or in error/hang-up) within
    ``timeout`` s (None: no limit).

    A poll object per call: one shared object would refuse concurrent use from two
    threads, and select() cannot take descriptors above FD_SETSIZE.
    """
    poller = select.poll()
    poller.register(fd, event)
    return bool(poller.poll(None if timeout is None else max(timeout, 0.0) * 1000.0))


def write_all(fd: int, data: bytes, timeout: float) -> None:
    """Write all of ``data`` to the non-blocking descriptor ``fd``, waiting in poll() for
    room; raise TimeoutError when bytes are still unwritten ``timeout`` s after the
    descriptor first had none (the device or peer stopped reading). OSError passes.

    The wait starts only when the descriptor is full. pyserial's ``write()`` with a
    ``write_timeout`` instead raises SerialTimeoutException whenever the timeout has
    expired by the time ``os.write`` returned, even if every byte was written: a thread
    descheduled under load then reported a frame that went out as lost, and the turret's
    slcan link was dropped for it (seen in the parallel test runs).
    """
    pending = memoryview(data)
    deadline: float | None = None
    while pending:
        try:
            pending = pending[os.write(fd, pending):]
        except BlockingIOError:
            now = time.monotonic()
            deadline = deadline or now + timeout
            if now >= deadline or not wait_ready(fd, select.POLLOUT, deadline - now):
                raise TimeoutError(f'no room to write for {timeout:g} s (the device does '
                                   'not read)') from None


def read_ready(fd: int, max_bytes: int, timeout: float | None) -> bytes | None:
    """Up to ``max_bytes`` bytes waiting on descriptor ``fd``, after up to ``timeout`` s
    for the first: None when none came, b'' when the descriptor is at its end (the peer
    or the device is gone).

    One poll() and one read(), the whole cost of a reader's wake-up. Python's socket
    timeout costs an ioctl per call, and pyserial's ``timeout`` re-applies the port's
    termios set-up while its ``in_waiting`` + ``read(n)`` add an ioctl and a second
    select(). Every byte reader of the suite (TCP, serial, the turret's slcan adapter)
    reads through this. ``fd`` must be non-blocking (sockets here, pyserial's ports).
    """
    if not wait_ready(fd, select.POLLIN, timeout):
        return None
    try:
        return os.read(fd, max_bytes)
    except BlockingIOError:
        return None


class SerialStream(ByteStream):
    """Serial-port link via pyserial (RS-232/422/485 adapters or a pseudo-terminal).

    pyserial is imported when a port is opened, so a node on a TCP link does not carry it
    (bench/README.md, "What a node imports"); its ``SerialException`` is an ``OSError``.
    The defaults are pyserial's ``EIGHTBITS``, ``PARITY_NONE`` and ``STOPBITS_ONE``.
    """

    def __init__(
        self,
        port: str,
        baudrate: int = 115200,
        bytesize: int = 8,
        parity: str = 'N',
        stopbits: float = 1,
    ) -> None:
        self.port = port
        self.baudrate = int(baudrate)
        self.write_timeout = 2.0
        self._settings = {'bytesize': bytesize, 'parity': parity, 'stopbits': stopbits}
        self._serial: serial.Serial | None = None
        self._write_lock = threading.Lock()

    @property
    def description(self) -> str:
        return f'serial://{self.port}?baudrate={self.baudrate}'

    @property
    def is_open(self) -> bool:
        return self._serial is not None

    def open(self) -> None:
        import serial

        self.close()
        try:
            self._serial = serial.Serial(
                self.port, self.baudrate, timeout=0.1, **self._settings
            )
        except (OSError, ValueError) as exc:  # serial.SerialException is an OSError
            raise TransportError(f'cannot open {self.description}: {exc}') from exc

    def close(self) -> None:
        port, self._serial = self._serial, None
        if port is not None:
            with contextlib.suppress(OSError):
                port.close()

    def _require(self) -> serial.Serial:
        port = self._serial
        if port is None:
            raise LinkClosed(f'{self.description} is not open')
        return port

    def write(self, data: bytes) -> None:
        """Write everything, waiting up to ``write_timeout`` for room (:func:`write_all` on
        the port's non-blocking descriptor, not pyserial's timed write)."""
        port = self._require()
        with self._write_lock:
            try:
                write_all(port.fileno(), data, self.write_timeout)
            except TimeoutError:
                raise LinkClosed(f'{self.description}: write stalled for '
                                 f'{self.write_timeout:g} s (the device does not read)') from None
            except (OSError, TypeError, AttributeError, ValueError) as exc:
                raise LinkClosed(f'{self.description}: write failed: {exc}') from exc

    def read(self, max_bytes: int, timeout: float) -> bytes:
        """:func:`read_ready` on the port's descriptor, not pyserial's ``timeout`` and
        ``read``: a streaming reader wakes 50-350 times a second, so the system calls per
        wake-up are its CPU."""
        port = self._require()
        try:
            data = read_ready(port.fileno(), max_bytes, max(timeout, 0.0))
        except (OSError, TypeError, AttributeError, ValueError) as exc:
            # A USB adapter or pty that disappears raises EIO; a port closed by another
            # thread has no descriptor.
            raise LinkClosed(f'{self.description}: read failed: {exc}') from exc
        if data is None:
            return b''
        if not data:  # readable and empty: the device went away
            raise LinkClosed(f'{self.description}: device reports readiness to read but '
                             'returned no data')
        return data


def read_exactly(stream: ByteStream, count: int, timeout: float) -> bytes:
    """Read ``count`` bytes or raise :class:`TimeoutError` when ``timeout`` expires first."""
    deadline = time.monotonic() + timeout
    buffer = bytearray()
    while len(buffer) < count:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError(f'{stream.description}: got {len(buffer)} of {count} bytes')
        buffer += stream.read(count - len(buffer), remaining)
    return bytes(buffer)
