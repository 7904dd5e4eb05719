"""The virtual gimbal's session: one request line in flight, one reply line (no ROS)."""

from __future__ import annotations

import time

from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout
from gimbal_driver_common.fair_lock import FairRLock
from gimbal_driver_common.transport import TcpStream

from .protocol import Refused, check_reply, verb


class VirtualGimbalClient:
    """Request/reply client with one request in flight (thread-safe)."""

    def __init__(self, host: str, port: int, timeout: float = 1.0) -> None:
        self.stream = TcpStream(host, port)
        self.timeout = timeout
        # fair: a command stream must not starve the joint poll (gimbal_driver_common.fair_lock)
        self._lock = FairRLock()
        self._buffer = b''

    def open(self) -> None:
        self.stream.open()
        self._buffer = b''

    def close(self) -> None:
        self.stream.close()

    def request(self, line: str) -> str:
        """Send ``line``; the reply line, DeviceRefused for ERR, DeviceTimeout for none."""
        with self._lock:
            self.stream.write(line.encode() + b'\n')
            deadline = time.monotonic() + self.timeout
            while b'\n' not in self._buffer:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeout(f'no reply to {verb(line)} within {self.timeout} s')
                self._buffer += self.stream.read(4096, remaining)
            reply, self._buffer = self._buffer.split(b'\n', 1)
        try:
            return check_reply(line, reply.decode('ascii', 'replace'))
        except Refused as exc:
            raise DeviceRefused(str(exc)) from None
