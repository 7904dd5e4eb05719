"""The U-Camera client's errors, its view of the gimbal and its counters (no ROS)."""

from __future__ import annotations

from dataclasses import dataclass

from gimbal_driver_common.errors import DeviceTimeout, GimbalError, LinkError

from .protocol import GimbalMode, ParserStats

PERSISTENT_MODES = frozenset({GimbalMode.ANGLES, GimbalMode.RATES, GimbalMode.STOW,
                              GimbalMode.PILOT})
ONE_SHOT_MODES = frozenset({GimbalMode.INIT, GimbalMode.GYRO_AUTOALIGN,
                            GimbalMode.FULL_AUTOALIGN, GimbalMode.FFC_CALIBRATION})


class UCameraError(GimbalError):
    """Base class of client errors; the message says what to check."""


class NotConnectedError(UCameraError, LinkError):
    """The serial link is down (the supervisor reopens it)."""


class RequestTimeoutError(UCameraError, DeviceTimeout):
    """The gimbal did not answer a request."""


@dataclass(frozen=True)
class GimbalState:
    """Latest reported values (None until first reported)."""

    mode: int | None = None
    pan: float | None = None
    tilt: float | None = None
    pan_rate: float | None = None
    tilt_rate: float | None = None
    zoom: float | None = None
    gimbal_type: int | None = None
    ir_palette: int | None = None
    latitude: float | None = None
    longitude: float | None = None
    altitude: float | None = None
    angles_time: float = 0.0  # time.time() when the last angles report arrived
    position_time: float = 0.0


@dataclass
class ClientStats(ParserStats):
    """Counters for diagnostics: the stream parser's (copied from it as bytes arrive;
    ``frames`` here counts the packets decoded) and the session's own."""

    unknown_packets: int = 0
    bad_payloads: int = 0
    reconnects: int = 0  # start() after an earlier session (the supervisor reopening)
    silences: int = 0
    commands_sent: int = 0
