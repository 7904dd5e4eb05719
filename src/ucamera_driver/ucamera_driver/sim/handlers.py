"""U-Camera simulator: the handling of received commands and requests (5.5)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

from gimbal_driver_common.sim_motion import AxisMotion
from gimbal_driver_common.sim_requests import RequestFaults

from ..protocol import (
    AntennaPositionReport,
    AntennaPositionRequest,
    ConfigureGpsFeed,
    GimbalMode,
    GimbalType,
    GpsFeed,
    GpsPositionVelocities,
    GpsVelocities,
    Packet,
    SaveConfiguration,
    SaveFfc,
    SetAngles,
    SetAntennaPosition,
    SetIrPalette,
    SetMode,
    SetRates,
    SetTelemetryRate,
    SetZoom,
    TelemetryRateReport,
    TelemetryRateRequest,
    VehicleAngles,
    VehicleAngularVelocities,
    VersionRequest,
    mode_name,
)

if TYPE_CHECKING:
    from .model import SimConfig

LOG = logging.getLogger("ucamera_sim")

#: the UCSP requests the gimbal answers, and the motion packets it acts on without an
#: answer (``mute``/``delay``/``ignore`` take these packet names; a delay of an unanswered
#: packet holds nothing)
REQUESTS = tuple(packet.__name__ for packet in (
    AntennaPositionRequest, TelemetryRateRequest, VersionRequest, SetMode, SetAngles,
    SetRates))


class CommandHandlers:
    """The commands of :class:`~.model.UCameraModel`, a base of it whose state they read
    and change."""

    # The model's state the handlers use (UCameraModel.__init__ sets each).
    config: SimConfig
    lock: threading.RLock
    _clock: Callable[[], float]
    pan: AxisMotion
    tilt: AxisMotion
    mode: GimbalMode
    mode_since: float
    angles_target: tuple[float, float]
    commanded_angles: tuple[float, float]
    commanded_rates: tuple[float, float]
    zoom_target: float
    telemetry_rate: int
    ir_palette: int
    gps_feed: GpsFeed
    antenna: tuple[float, float, float]
    external_position: tuple[float, float, float] | None
    external_velocity: tuple[float, float, float] | None
    vehicle_angles: tuple[float, float, float] | None
    vehicle_rates: tuple[float, float, float] | None
    busy_until: float
    nv_saves: int
    ffc_saves: int
    nv: dict[str, object]
    received: dict[str, int]
    ignored: dict[str, int]
    request_faults: RequestFaults

    # --- commands --------------------------------------------------------
    def handle(self, packet: Packet) -> list[Packet]:
        """Apply one received packet; return the immediate answers."""
        now = self._clock()
        with self.lock:
            name = type(packet).__name__
            if now < self.busy_until:
                self.ignored[name] = self.ignored.get(name, 0) + 1
                return []
            self.received[name] = self.received.get(name, 0) + 1
            if self.request_faults.muted(name):
                return []  # mute: received and dropped, never answered
            if self.request_faults.ignored(name) and not name.endswith('Request'):
                return []  # ignore: a setter answers nothing anyway; not acted on
            answers: list[Packet] = []
            if isinstance(packet, SetMode):
                if packet.mode in set(GimbalMode):
                    self._set_mode(GimbalMode(packet.mode), now)
                else:
                    self.ignored[name] = self.ignored.get(name, 0) + 1
            elif isinstance(packet, SetAngles):
                self.commanded_angles = (packet.pan, packet.tilt)
                if self.mode == GimbalMode.ANGLES:
                    self.angles_target = self.commanded_angles
            elif isinstance(packet, SetRates):
                if self.mode == GimbalMode.RATES:
                    self.commanded_rates = (packet.pan, packet.tilt)
            elif isinstance(packet, SetZoom):
                self.zoom_target = packet.level
            elif isinstance(packet, SetTelemetryRate):
                if 1 <= packet.rate_hz <= 200:  # 5.5.2.5: 1 to 200 Hz
                    self.telemetry_rate = int(packet.rate_hz)
                else:
                    self.ignored[name] = self.ignored.get(name, 0) + 1
            elif isinstance(packet, TelemetryRateRequest):
                answers.append(TelemetryRateReport(self.telemetry_rate))
            elif isinstance(packet, VersionRequest):
                answers.append(self.config.version)
            elif isinstance(packet, SetAntennaPosition):
                self.antenna = (packet.x, packet.y, packet.z)
            elif isinstance(packet, AntennaPositionRequest):
                answers.append(AntennaPositionReport(*self.antenna))
            elif isinstance(packet, ConfigureGpsFeed):
                self.gps_feed = GpsFeed(packet.source)
            elif isinstance(packet, GpsPositionVelocities):
                self.external_position = (packet.latitude, packet.longitude, packet.altitude)
                self.external_velocity = (packet.north, packet.east, packet.down)
            elif isinstance(packet, GpsVelocities):
                self.external_velocity = (packet.north, packet.east, packet.down)
            elif isinstance(packet, VehicleAngles):
                self.vehicle_angles = (packet.yaw, packet.pitch, packet.roll)
            elif isinstance(packet, VehicleAngularVelocities):
                self.vehicle_rates = (packet.yaw_rate, packet.pitch_rate, packet.roll_rate)
            elif isinstance(packet, SetIrPalette):
                if self.config.gimbal_type == GimbalType.IR:
                    self.ir_palette = int(packet.palette)
            elif isinstance(packet, SaveConfiguration):
                self.nv = {"telemetry_rate": self.telemetry_rate, "antenna": self.antenna,
                           "gps_feed": self.gps_feed, "ir_palette": self.ir_palette}
                self.nv_saves += 1
                self.busy_until = now + self.config.save_pause
            elif isinstance(packet, SaveFfc):
                # 5.5.1.2 does not say the gimbal goes quiet (the IR module saves)
                if self.config.gimbal_type == GimbalType.IR:
                    self.ffc_saves += 1
            else:  # a report sent to the gimbal: a real device would ignore it
                self.ignored[name] = self.ignored.get(name, 0) + 1
            return answers

    def _set_mode(self, mode: GimbalMode, now: float) -> None:
        if self.mode == GimbalMode.INIT:
            return  # initialising: mode commands are ignored until it finishes
        if mode == GimbalMode.FFC_CALIBRATION and self.config.gimbal_type != GimbalType.IR:
            return  # IR only
        if mode == self.mode:
            return  # periodic refresh of the same mode changes nothing
        if mode == GimbalMode.ANGLES:
            self.angles_target = (self.pan.position, self.tilt.position)
            self.commanded_angles = self.angles_target
        if mode == GimbalMode.RATES:
            self.commanded_rates = (0.0, 0.0)
        LOG.info("mode %s -> %s", mode_name(self.mode), mode_name(mode))
        self.mode = mode
        self.mode_since = now
