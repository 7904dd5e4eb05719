"""The virtual gimbal's session: request lines answered one reply line each, in order
(no ROS)."""

from __future__ import annotations

import time
from collections.abc import Sequence

from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout, GimbalError, LinkError
from gimbal_driver_common.fair_lock import FairRLock
from gimbal_driver_common.transport import TcpStream

from .protocol import Refused, check_reply, verb


class VirtualGimbalClient:
    """Request/reply client (thread-safe). A request waits for its reply; :meth:`post`
    writes requests whose replies are read later, by :meth:`finish_posted` or by the next
    request (replies come in the order of the requests)."""

    def __init__(self, host: str, port: int, timeout: float = 1.0) -> None:
        self.stream = TcpStream(host, port)
        self.timeout = timeout
        # fair: a command stream must not starve the joint poll (gimbal_driver_common.fair_lock)
        self._lock = FairRLock()
        self._buffer = b''
        self._posted: list[str] = []  # written by post(), replies not read yet
        self._posted_error: GimbalError | None = None

    def open(self) -> None:
        with self._lock:
            self.stream.open()
            self._buffer = b''
            if self._posted:  # the link closed before their replies came
                self._posted_error = LinkError(
                    f'link lost before the reply to {verb(self._posted[0])}')
                self._posted = []

    def close(self) -> None:
        self.stream.close()

    def request(self, line: str) -> str:
        """Send ``line``; the reply line, DeviceRefused for ERR, DeviceTimeout for none."""
        with self._lock:
            self._settle_posted()
            self.stream.write(line.encode() + b'\n')
            reply = self._reply_to(line)
        try:
            return check_reply(line, reply)
        except Refused as exc:
            raise DeviceRefused(str(exc)) from None

    def post(self, lines: Sequence[str]) -> bool:
        """Write ``lines`` in one write without waiting for their replies: True when
        written. False, with nothing written, when another thread holds the link (never
        waited for: the joint_command callback calls this) or an earlier post is unread."""
        if not self._lock.acquire(blocking=False):
            return False
        try:
            if self._posted:
                return False
            self.stream.write(b''.join(line.encode() + b'\n' for line in lines))
            self._posted = list(lines)
            return True
        finally:
            self._lock.release()

    def finish_posted(self) -> None:
        """Read the replies of the last :meth:`post` if no request has yet; raise the first
        ERR among them (DeviceRefused), or the timeout or lost link that cut them off."""
        with self._lock:
            self._settle_posted()
            error, self._posted_error = self._posted_error, None
        if error is not None:
            raise error

    def _settle_posted(self) -> None:
        """Read the posted requests' replies (caller holds the lock); keep their first
        error for finish_posted. A timeout also fails the request that found them."""
        posted, self._posted = self._posted, []
        for line in posted:
            try:
                check_reply(line, self._reply_to(line))
            except Refused as exc:
                self._posted_error = self._posted_error or DeviceRefused(str(exc))
            except DeviceTimeout as exc:
                self._posted_error = self._posted_error or exc
                raise

    def _reply_to(self, line: str) -> str:
        """The next reply line (caller holds the lock); DeviceTimeout when none comes."""
        deadline = time.monotonic() + self.timeout
        while b'\n' not in self._buffer:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DeviceTimeout(f'no reply to {verb(line)} within {self.timeout} s')
            self._buffer += self.stream.read(4096, remaining)
        reply, self._buffer = self._buffer.split(b'\n', 1)
        return reply.decode('ascii', 'replace')
