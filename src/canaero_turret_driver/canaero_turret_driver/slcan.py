"""slcan (Lawicel ASCII) on a serial port, read in whole chunks instead of byte by byte.

python-can's `slcanBus` reads the port one byte per `read(1)`, and while the port is
idle it polls with the port's 1 ms read timeout, so every `recv()` costs about a
thousand select() calls per second plus one Python round trip per received byte (a
CANaerospace frame is a 14..22 byte record). That was most of the node's CPU at its
default rate. `ChunkedSlcanBus` keeps everything else of `slcanBus` (open/close and
bitrate commands, frame parsing, send) and replaces only the reading: it sleeps in
poll() on the port's file descriptor until bytes arrive (or the timeout ends), reads
all waiting bytes at once with one read() on the descriptor
(`gimbal_driver_common.transport.read_ready`) and splits them into records at CR (OK) or
BEL (error).

Written against python-can 4.6.1 (pinned in requirements.txt): it overrides the
private `_read`, `_write` and `flush` of `slcanBus`; re-check them when upgrading
python-can.
"""

from __future__ import annotations

import re
from collections import deque
from typing import Any

import can
import serial
from can.exceptions import error_check
from can.interfaces.slcan import slcanBus

from gimbal_driver_common.transport import read_ready, write_all

# A record ends at CR (also the adapter's bare OK) or BEL (the adapter's error reply).
RECORD = re.compile(rb"[^\r\x07]*[\r\x07]")
MAX_RECORD = 64  # longer than any slcan record of a classic CAN frame (T + 8 + 1 + 16)
#: how long a send without a timeout of its own waits for room (the adapter stopped reading)
SEND_TIMEOUT_S = 2.0


class ChunkedSlcanBus(slcanBus):
    """`slcanBus` that reads whole chunks and sleeps in poll() instead of polling the port."""

    def __init__(self, channel: str, **kwargs: Any) -> None:
        self._records: deque[str] = deque()
        self._pending = bytearray()
        super().__init__(channel, **kwargs)

    def _receive(self, timeout: float | None) -> bytes:
        """The bytes waiting on the port, after up to `timeout` s for the first (b"" if
        none came): the suite's one descriptor read (`transport.read_ready`, one poll()
        and one read()); the wake-up per burst of frames is most of the receive thread's
        CPU."""
        port = self.serialPortOrig
        try:
            fd = port.fileno()
        except (AttributeError, OSError, ValueError, NotImplementedError):
            # A URL port without a descriptor (socket://, loop://): wait in its own read.
            return port.read(1)
        data = read_ready(fd, 4096, timeout)
        if data is None:
            return b""
        if not data:  # readable and empty: the adapter (or pty) went away
            raise serial.SerialException("device reports readiness to read but returned no data")
        return data

    def _split(self, data: bytes) -> None:
        """Append bytes and move every complete record (terminator included) to the queue."""
        self._pending += data
        end = 0
        for match in RECORD.finditer(self._pending):
            self._records.append(match.group().decode("ascii", "replace"))
            end = match.end()
        del self._pending[:end]
        if len(self._pending) > MAX_RECORD:  # no terminator in sight: resynchronise
            self._records.append(self._pending.decode("ascii", "replace") + "\a")
            self._pending.clear()

    def _read(self, timeout: float | None) -> str | None:
        expiry = serial.Timeout(timeout)
        with error_check("Could not read from serial device"):
            while not self._records:
                data = self._receive(expiry.time_left())
                if data:
                    self._split(data)
                elif expiry.expired():
                    return None
            return self._records.popleft()

    def _write(self, string: str) -> None:
        """One record to the adapter (`slcanBus._write` without its pyserial write):
        :func:`write_all` on the port's descriptor, bounded by the send's timeout.

        pyserial's timed `write()` reported a record that went out as a write timeout when
        the sending thread was descheduled past the timeout (the turret link dropped under
        load), and `slcanBus._write`'s `flush()` (tcdrain) waits without a bound for a pty
        or adapter to take the bytes: the kernel sends what was written anyway.
        """
        port = self.serialPortOrig
        data = string.encode() + self.LINE_TERMINATOR
        with error_check("Could not write to serial device"):
            try:
                fd = port.fileno()
            except (AttributeError, OSError, ValueError, NotImplementedError):
                port.write(data)  # a URL port without a descriptor
                return
            timeout = port.write_timeout
            write_all(fd, data, SEND_TIMEOUT_S if timeout is None else timeout)

    def flush(self) -> None:
        self._records.clear()
        self._pending.clear()
        super().flush()


def open_bus(interface: str, channel: str, **options: Any) -> can.BusABC:
    """`can.Bus(...)`, except that `slcan` gets the chunked reader of this module."""
    if interface == "slcan":
        return ChunkedSlcanBus(channel, **options)
    return can.Bus(interface=interface, channel=channel, **options)
