"""The kOS client's errors, its view of the motors and playback, and discovery (no ROS)."""

from __future__ import annotations

import contextlib
import socket
import time
from collections import deque
from dataclasses import dataclass, field

from gimbal_driver_common import errors

from .protocol import (
    UNCALIBRATED_TARGET,
    FrameParser,
    NetworkInfo,
    PlaybackState,
    ProtocolError,
    decode,
)
from .protocol.trajectory import AxisLimits


class KosError(errors.GimbalError):
    """Base of the client's errors (in the shared hierarchy); messages say what to do."""


class NotConnected(KosError, errors.LinkError):
    """No link (unreachable, no discovery datagram, USB device missing) or the link dropped."""


class DeviceTimeout(KosError, errors.DeviceTimeout):
    """The device did not answer a Get in time."""


class MessageUnsupported(KosError, errors.Unsupported):
    """The device answered a request with UnsupportedMessage: it answered, it is not silent."""


class PasswordRejected(KosError, errors.DeviceRefused):
    """The password does not match (checked locally) or the device locked us out."""


class CommandRejected(KosError, errors.DeviceRefused):
    """A command refused before sending (limits, unknown motor) or by the device."""


#: s: the shortest span of position reports a speed is taken over. kOS reports positions,
#: not speeds, and a report is timed when it is read, not when the device measured it: two
#: reports read in one burst (a loaded machine, a delayed TCP segment) span microseconds,
#: and their difference over that read as tens of rad/s, or as rest when the device had
#: not moved between them. The stop confirmation took that rest as the axis's, and a
#: dropped stop went unnoticed (2026-12-02 CI). Over 0.1 s the reading jitter is a few
#: per cent of the span; the speed lags the motion by about half of it.
VELOCITY_SPAN_S = 0.1


@dataclass
class MotorState:
    address: int
    position: float = 0.0          # rotations
    velocity: float = 0.0          # rotations/s (over VELOCITY_SPAN_S of reports: report)
    begin_position: float = 0.0
    end_position: float = 0.0
    max_setup_speed: float = 0.0
    max_move_speed: float = 0.0
    max_acceleration: float = 0.0
    is_fiz: bool = False
    online: bool = True
    stamp: float = 0.0             # time.time() of the last position report
    last_error: int | None = None
    #: (time, position) of the reports of the last VELOCITY_SPAN_S and one before
    recent: deque[tuple[float, float]] = field(default_factory=deque, repr=False,
                                             compare=False)

    def report(self, position: float, now: float) -> None:
        """A position the device reported, read at ``now``: the speed is the travel since
        the newest report at least :data:`VELOCITY_SPAN_S` older (none yet: unchanged)."""
        recent = self.recent
        while len(recent) > 1 and now - recent[1][0] >= VELOCITY_SPAN_S:
            recent.popleft()
        if recent and now - recent[0][0] >= VELOCITY_SPAN_S:
            self.velocity = (position - recent[0][1]) / (now - recent[0][0])
        recent.append((now, position))
        self.position, self.stamp = position, now

    @property
    def calibrated(self) -> bool:
        return self.end_position != 0.0

    def travel(self) -> tuple[float, float]:
        """Allowed target range in rotations."""
        if self.calibrated:
            return (min(self.begin_position, self.end_position),
                    max(self.begin_position, self.end_position))
        return -UNCALIBRATED_TARGET, UNCALIBRATED_TARGET

    def limits(self) -> AxisLimits:
        return AxisLimits(self.begin_position, self.end_position, self.max_move_speed,
                          self.max_acceleration)


@dataclass
class PlaybackInfo:
    status: int = PlaybackState.NO_MOVE
    elapsed: float = 0.0
    photo_count: int = 0
    positions: dict[int, float] = field(default_factory=dict)
    loaded: bool = False           # TrajectoryData accepted and not yet consumed by FullStop
    set_up: bool = False
    history: list[int] = field(default_factory=list)   # statuses since the last load


@dataclass
class ErrorEvent:
    code: int
    motor_address: int
    description: str
    stamp: float


def discover(discovery_port: int, timeout: float, bind_address: str = '0.0.0.0') -> str:
    """Listen for NetworkInfo datagrams; return the first device's IP address as text."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((bind_address, discovery_port))
    except OSError as exc:
        sock.close()
        raise NotConnected(f'cannot listen for discovery on UDP {bind_address}:'
                           f'{discovery_port}: {exc}') from exc
    deadline = time.monotonic() + timeout
    try:
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise NotConnected(
                    f'no kOS device announced itself on UDP port {discovery_port} within '
                    f'{timeout:.1f} s; set the host parameter or check the network')
            sock.settimeout(remaining)
            try:
                data, sender = sock.recvfrom(2048)
            except TimeoutError:
                continue
            for frame in FrameParser().feed(data):
                with contextlib.suppress(ProtocolError):
                    message = decode(frame)
                    if isinstance(message, NetworkInfo):
                        # The datagram's source is what we can reach; the payload may carry
                        # a private address behind NAT.
                        return message.ip_text if message.ip_address else sender[0]
    finally:
        sock.close()
