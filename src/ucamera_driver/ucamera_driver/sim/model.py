"""U-Camera simulator: the device model (modes, motion, zoom, periodic reports)."""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from gimbal_driver_common.sim_motion import AxisMotion
from gimbal_driver_common.sim_requests import RequestFaults

from ..protocol import (
    AnglesReport,
    GimbalMode,
    GimbalType,
    GimbalTypeReport,
    GpsFeed,
    IrPaletteReport,
    ModeReport,
    Packet,
    RatesReport,
    SystemPositionReport,
    VersionReport,
    ZoomReport,
    mode_name,
)
from .handlers import CommandHandlers

LOG = logging.getLogger("ucamera_sim")

PAN_LIMITS = (-math.pi, math.pi)
TILT_LIMITS = (-math.pi / 2, math.pi / 2)
STOW_POSITION = (0.0, math.pi / 2)  # 4.2: tilt +90, pan 0
PILOT_POSITION = (0.0, 0.0)
FFC_POSITION = (0.0, math.pi / 2)  # 4.7
AUTOMATIC_MODES = {GimbalMode.INIT, GimbalMode.GYRO_AUTOALIGN, GimbalMode.FULL_AUTOALIGN,
                   GimbalMode.FFC_CALIBRATION}


@dataclass
class SimConfig:
    """Tunable behaviour; durations are short so tests stay fast."""

    gimbal_type: GimbalType = GimbalType.IR
    telemetry_rate: int = 50
    max_rate: float = math.radians(60.0)  # rad/s
    acceleration: float = math.radians(240.0)  # rad/s^2
    zoom_speed: float = 1.0 / 3.0  # fraction per second (full range in 3 s)
    init_time: float = 0.5
    autoalign_time: float = 2.0
    ffc_time: float = 1.0
    save_pause: float = 1.0
    latitude: float = 40.4168
    longitude: float = -3.7038
    altitude: float = 650.0
    version: VersionReport = field(
        default_factory=lambda: VersionReport(1201, 2304, 30105, 30102, 7)
    )


class UCameraModel(CommandHandlers):
    """Device state and behaviour, independent of the link (survives link drops)."""

    def __init__(self, config: SimConfig | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config or SimConfig()
        self._clock = clock
        self.lock = threading.RLock()
        cfg = self.config
        self.pan = AxisMotion(cfg.max_rate, cfg.acceleration, min_position=PAN_LIMITS[0],
                              max_position=PAN_LIMITS[1])
        self.tilt = AxisMotion(cfg.max_rate, cfg.acceleration, min_position=TILT_LIMITS[0],
                               max_position=TILT_LIMITS[1])
        self.mode = GimbalMode.INIT
        self.mode_since = clock()
        self.angles_target = (0.0, 0.0)
        self.commanded_angles = (0.0, 0.0)
        self.commanded_rates = (0.0, 0.0)
        self.zoom = 0.0
        self.zoom_target = 0.0
        self.telemetry_rate = self.config.telemetry_rate
        self.ir_palette = 0
        self.gps_feed = GpsFeed.INTERNAL
        self.antenna = (0.0, 0.0, 0.0)
        self.external_position: tuple[float, float, float] | None = None
        self.external_velocity: tuple[float, float, float] | None = None
        self.vehicle_angles: tuple[float, float, float] | None = None
        #: the on-board GPS position (deg, deg, m; the `gnss` verb moves it)
        self.internal_position = (self.config.latitude, self.config.longitude,
                                  self.config.altitude)
        self.vehicle_rates: tuple[float, float, float] | None = None
        self.busy_until = 0.0  # NV write in progress: no telemetry, commands ignored
        self.nv_saves = 0
        self.ffc_saves = 0
        self.nv: dict[str, object] = {}
        self.received: dict[str, int] = {}
        self.ignored: dict[str, int] = {}
        #: requests never answered (``mute``: received, dropped) or answered late
        #: (``delay``: the session holds the answer), by packet name (:data:`REQUESTS`)
        self.request_faults = RequestFaults()
        self._last_step = clock()

    # --- simulation step -------------------------------------------------
    def step(self, now: float | None = None) -> None:
        now = self._clock() if now is None else now
        with self.lock:
            dt = min(max(now - self._last_step, 0.0), 0.1)
            self._last_step = now
            cfg = self.config
            if self.mode == GimbalMode.RATES:
                for axis, rate in zip((self.pan, self.tilt), self.commanded_rates, strict=True):
                    axis.jog(rate)
            else:
                for axis, goal in zip((self.pan, self.tilt), self._mode_target(), strict=True):
                    axis.move_to(goal)
            for axis in (self.pan, self.tilt):
                axis.step(dt)
            self._finish_automatic_mode(now)
            zoom_step = cfg.zoom_speed * dt
            self.zoom += max(-zoom_step, min(zoom_step, self.zoom_target - self.zoom))

    def _mode_target(self) -> tuple[float, float]:
        if self.mode == GimbalMode.ANGLES:
            return self.angles_target
        if self.mode == GimbalMode.STOW:
            return STOW_POSITION
        if self.mode == GimbalMode.FFC_CALIBRATION:
            return FFC_POSITION
        return PILOT_POSITION  # pilot, init, autoalign

    def _at(self, target: tuple[float, float]) -> bool:
        return (abs(self.pan.position - target[0]) < 1e-4
                and abs(self.tilt.position - target[1]) < 1e-4)

    def _finish_automatic_mode(self, now: float) -> None:
        if self.mode not in AUTOMATIC_MODES:
            return
        duration = {
            GimbalMode.INIT: self.config.init_time,
            GimbalMode.GYRO_AUTOALIGN: self.config.autoalign_time,
            GimbalMode.FULL_AUTOALIGN: self.config.autoalign_time,
            GimbalMode.FFC_CALIBRATION: self.config.ffc_time,
        }[self.mode]
        if not self._at(self._mode_target()):
            self.mode_since = now  # the timer starts once the pose is reached
            return
        if now - self.mode_since >= duration:
            LOG.info("%s finished -> angles", mode_name(self.mode))
            self.mode = GimbalMode.ANGLES
            self.mode_since = now
            self.angles_target = self.commanded_angles

    # --- reports ---------------------------------------------------------
    def silent(self, now: float | None = None) -> bool:
        return (self._clock() if now is None else now) < self.busy_until

    def periodic_reports(self) -> list[Packet]:
        with self.lock:
            if self.gps_feed == GpsFeed.EXTERNAL and self.external_position is not None:
                position = self.external_position
            else:
                position = self.internal_position
            reports: list[Packet] = [
                ModeReport(self.mode),
                AnglesReport(self.pan.position, self.tilt.position),
                RatesReport(self.pan.velocity, self.tilt.velocity),
                ZoomReport(round(self.zoom * 16383) / 16383),
                GimbalTypeReport(self.config.gimbal_type),
                SystemPositionReport(*position),
            ]
            if self.config.gimbal_type == GimbalType.IR:
                reports.append(IrPaletteReport(self.ir_palette))
            return reports
