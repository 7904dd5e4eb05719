"""A python-can bus as a session link (no ROS): frames in, frames out, errors as LinkError.

Any python-can interface (socketcan on a robot, slcan over a pty or the TCP bridge, the
virtual bus of the tests). An adapter that sends bytes it cannot parse is not a lost link:
python-can's slcan keeps an undecodable partial record in its buffer (every later record
then fails too), so the receive buffer is flushed and :class:`Garbled` is handed to the
client, which counts it and gives the link up when records keep failing.
"""

from __future__ import annotations

import contextlib
import threading
from dataclasses import dataclass

import can

from gimbal_driver_common.session import Link

from .client_types import LinkError


@dataclass(frozen=True)
class Garbled:
    """The adapter delivered a record that could not be parsed (already flushed)."""

    error: BaseException


class CanLink(Link):
    """One open `can.BusABC`; :meth:`close` shuts it down."""

    def __init__(self, bus: can.BusABC, description: str, send_timeout: float = 0.2) -> None:
        self.bus = bus
        self.description = description
        self.send_timeout = send_timeout
        self._send_lock = threading.Lock()

    def read(self, timeout: float) -> can.Message | Garbled | None:
        try:
            return self.bus.recv(timeout=timeout)
        except (ValueError, IndexError) as exc:  # slcan/serial: a garbled ASCII record
            return self._flush(exc)
        except (can.CanError, OSError) as exc:
            if isinstance(exc.__cause__, ValueError | IndexError):
                # python-can wraps an undecodable byte sequence in CanOperationError.
                return self._flush(exc.__cause__)
            raise LinkError(f"receive failed: {exc}") from exc
        except Exception as exc:
            raise LinkError(f"receive failed unexpectedly: {exc!r}") from exc

    def _flush(self, error: BaseException) -> Garbled:
        flush = getattr(self.bus, "flush", None)
        if callable(flush):
            with contextlib.suppress(Exception):
                flush()
        return Garbled(error)

    def write(self, frame: can.Message) -> None:
        try:
            with self._send_lock:
                self.bus.send(frame, timeout=self.send_timeout)
        except (can.CanError, OSError, ValueError) as exc:
            raise LinkError(f"send failed: {exc}") from exc

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.bus.shutdown()
