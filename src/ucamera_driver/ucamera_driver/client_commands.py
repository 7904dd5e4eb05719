"""The U-Camera client's device-function commands (no ROS): zoom, telemetry rate, IR
palette, the external GPS/IMU feed, the antenna position and the non-volatile saves, each
one packet in the device frame.

A part of :class:`~.client.UCameraClient` (its ``commands`` attribute), kept apart so the
session (lifecycle, requests, motion commands, reader thread, refresh) reads in one
sitting; it is handed the link it writes to (:class:`CommandLink`) and the quiet period
the NV save opens (:class:`QuietPeriod`, which the session's silence check reads).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Protocol

from .protocol import (
    ConfigureGpsFeed,
    GpsFeed,
    GpsPositionVelocities,
    GpsVelocities,
    Packet,
    SaveConfiguration,
    SaveFfc,
    SetAntennaPosition,
    SetIrPalette,
    SetTelemetryRate,
    SetZoom,
    VehicleAngles,
    VehicleAngularVelocities,
)


class CommandLink(Protocol):
    """What the commands use of the client: its writes and one request."""

    def send(self, packet: Packet) -> None:
        """Encode (range-checked first) and write one packet."""

    def request_telemetry_rate(self, timeout: float | None = None) -> int:
        """The report rate the gimbal says it uses."""


@dataclass
class QuietPeriod:
    """After an NV save the gimbal goes quiet for about 1 s: until ``until`` (monotonic)
    the silence check allows ``grace`` s more."""

    grace: float
    until: float = 0.0

    def begin(self) -> None:
        self.until = time.monotonic() + self.grace

    def extra(self, now: float) -> float:
        """The silence allowed on top of the usual at ``now``."""
        return self.grace if now < self.until else 0.0


class UCameraCommands:
    """The device-function commands of :class:`~.client.UCameraClient`."""

    def __init__(self, link: CommandLink, quiet: QuietPeriod) -> None:
        self._link = link
        self._quiet = quiet

    def send(self, packet: Packet) -> None:
        self._link.send(packet)

    def set_zoom(self, level: float) -> None:
        self.send(SetZoom(level))

    def set_telemetry_rate(self, rate_hz: int, verify: bool = True) -> int:
        """Set the periodic report rate; with ``verify`` read it back and return it."""
        self.send(SetTelemetryRate(rate_hz))
        return self._link.request_telemetry_rate() if verify else int(rate_hz)

    def set_ir_palette(self, palette: int) -> None:
        self.send(SetIrPalette(palette))

    def configure_gps_feed(self, source: GpsFeed) -> None:
        self.send(ConfigureGpsFeed(source))

    def send_gps(self, latitude: float, longitude: float, altitude: float,
                 north: float, east: float, down: float) -> None:
        self.send(GpsPositionVelocities(latitude, longitude, altitude, north, east, down))

    def send_gps_velocity(self, north: float, east: float, down: float) -> None:
        self.send(GpsVelocities(north, east, down))

    def send_vehicle_angles(self, yaw: float, pitch: float, roll: float) -> None:
        self.send(VehicleAngles(yaw, pitch, roll))

    def send_vehicle_rates(self, yaw_rate: float, pitch_rate: float, roll_rate: float) -> None:
        self.send(VehicleAngularVelocities(yaw_rate, pitch_rate, roll_rate))

    def set_antenna_position(self, x: float, y: float, z: float) -> None:
        self.send(SetAntennaPosition(x, y, z))

    def save_configuration(self) -> None:
        """NV write: the gimbal goes quiet ~1 s, which is not treated as silence."""
        self._quiet.begin()
        self.send(SaveConfiguration())

    def save_ffc(self) -> None:
        self.send(SaveFfc())
