"""The virtual gimbal's session: request lines answered one reply line each, in order
(no ROS).

It logs through :mod:`logging` (``virtual_gimbal_driver.client``), as every driver's
library code does; the node's log bridge (``gimbal_driver_common.ros.log_bridge``) takes
the lines to the node's ROS logger and /rosout.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence

from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout, LinkError
from gimbal_driver_common.link_lock import LinkLock
from gimbal_driver_common.transport import TcpStream

from .protocol import Refused, check_reply, verb

LOG = logging.getLogger(__name__)
#: how many discarded bytes a warning shows
SHOWN_BYTES = 40


class VirtualGimbalClient:
    """Request/reply client (thread-safe). Every exchange holds the device's link lock
    (``link_lock``: the adapter passes ``Device.link_lock``; alone, the client makes its
    own). :meth:`post` writes requests whose replies :meth:`settle` reads later; the
    core's link lock runs that before the link's next exchange (replies come in the
    order of the requests)."""

    def __init__(self, host: str, port: int, timeout: float = 1.0,
                 link_lock: LinkLock | None = None) -> None:
        self.stream = TcpStream(host, port)
        self.timeout = timeout
        self._lock = link_lock if link_lock is not None else LinkLock()
        self._buffer = b''
        self._opened = 0  # connections made: a post outlives none

    def open(self) -> None:
        with self._lock:
            self.stream.open()
            self._buffer = b''
            self._opened += 1

    def close(self) -> None:
        self.stream.close()

    def request(self, line: str) -> str:
        """Send ``line``; the reply line, DeviceRefused for ERR, DeviceTimeout for none."""
        with self._lock:
            self._discard_unsolicited()
            self.stream.write(line.encode() + b'\n')
            reply = self._reply_to(line)
        try:
            return check_reply(line, reply)
        except Refused as exc:
            raise DeviceRefused(str(exc)) from None

    def post(self, lines: Sequence[str]) -> tuple[int, list[str]]:
        """Write ``lines`` in one write without waiting for their replies (the caller, the
        core's command path, holds the link lock); returns what :meth:`settle` takes."""
        with self._lock:  # reentrant: the caller's hold
            self._discard_unsolicited()
            self.stream.write(b''.join(line.encode() + b'\n' for line in lines))
            return self._opened, list(lines)

    def settle(self, posted: tuple[int, list[str]]) -> None:
        """Read the replies of a :meth:`post`, in order; raise the first ERR among them
        (DeviceRefused), or the timeout or lost link that cut them off."""
        opened, lines = posted
        with self._lock:
            if opened != self._opened:
                raise LinkError(f'link lost before the reply to {verb(lines[0])}')
            refused: DeviceRefused | None = None
            for line in lines:
                try:
                    check_reply(line, self._reply_to(line))
                except Refused as exc:
                    refused = refused or DeviceRefused(str(exc))
        if refused is not None:
            raise refused

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

    def _discard_unsolicited(self) -> None:
        """Drop what arrived while no request was out (caller holds the lock, every posted
        reply settled): noise, or a reply that came after its request timed out, which the
        next request would otherwise take for its own reply."""
        stale, self._buffer = self._buffer, b''
        while data := self.stream.read(4096, 0.0):
            stale += data
        if stale:
            LOG.warning('discarded %d bytes that no request asked for (noise, or a reply '
                        'after its timeout): %r', len(stale), stale[:SHOWN_BYTES])
