"""The U-Camera client's device-function commands (no ROS): zoom, telemetry rate, IR
palette, the external GPS/IMU feed, the antenna position and the non-volatile saves, each
one packet in the device frame.

A mixin of :class:`~.client.UCameraClient`, kept apart so the session (lifecycle,
requests, motion commands, reader thread, refresh) reads in one sitting; the client
provides ``send``, ``request_telemetry_rate`` and the quiet-period state the NV save sets.
"""

from __future__ import annotations

import time

from .protocol import (
    ConfigureGpsFeed,
    GpsFeed,
    GpsPositionVelocities,
    GpsVelocities,
    SaveConfiguration,
    SaveFfc,
    SetAntennaPosition,
    SetIrPalette,
    SetTelemetryRate,
    SetZoom,
    VehicleAngles,
    VehicleAngularVelocities,
)


class UCameraCommands:
    """The device-function commands of :class:`~.client.UCameraClient` (a mixin)."""

    save_pause_grace: float
    _quiet_until: float

    def set_zoom(self, level: float) -> None:
        self.send(SetZoom(level))

    def set_telemetry_rate(self, rate_hz: int, verify: bool = True) -> int:
        """Set the periodic report rate; with ``verify`` read it back and return it."""
        self.send(SetTelemetryRate(rate_hz))
        return self.request_telemetry_rate() if verify else int(rate_hz)

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
        self._quiet_until = time.monotonic() + self.save_pause_grace
        self.send(SaveConfiguration())

    def save_ffc(self) -> None:
        self.send(SaveFfc())
