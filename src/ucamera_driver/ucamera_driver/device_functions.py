"""The U-Camera's device extras (no ROS): modes, telemetry and refresh rates, zoom, IR
palette, the external feed (ENU/FLU in, NED/FRD out) and the non-volatile saves behind
``allow_nv_write``. A part of :class:`~.device.UCameraDevice` (its ``functions``
attribute), kept apart so the adapter's core (signs, set-point ramp, moving bits, link)
reads in one sitting; the node's topics and services call these. It is handed the client,
the settings and the adapter's motion (:class:`AxesRelease`: a device mode takes the axes
from the driver's set-point, ramp and jog), and owns the vehicle attitude last sent.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout, InvalidRequest
from gimbal_driver_common.geodesy import Attitude
from gimbal_driver_common.orientation import euler_from_quaternion, wrap_angle

from .client import UCameraClient
from .protocol import MODE_NAMES, GimbalMode, GimbalType, mode_name

if TYPE_CHECKING:
    from .device import UCameraSettings

#: modes the gimbal leaves by itself (set_mode says so)
SELF_ENDING_MODES = (GimbalMode.GYRO_AUTOALIGN, GimbalMode.FULL_AUTOALIGN,
                     GimbalMode.FFC_CALIBRATION, GimbalMode.INIT)


def enu_flu_to_ned_frd(roll: float, pitch: float, yaw: float) -> tuple[float, float, float]:
    """REP-103 attitude (ENU world, FLU body) -> aerospace yaw, pitch, roll (NED/FRD).

    Roll keeps its sign, pitch flips (FLU nose-down positive, FRD nose-up
    positive) and yaw turns from "east, counter-clockwise" to "north, clockwise".
    """
    return wrap_angle(math.pi / 2 - yaw), -pitch, roll


class AxesRelease(Protocol):
    """What the functions use of the adapter's motion."""

    def release_axes(self, then: Callable[[], None]) -> None:
        """End the driver's set-point, ramp and jog, and run ``then`` (the command that
        hands the axes to a device mode) before any other motion command can start."""


class UCameraFunctions:
    """The device extras of :class:`~.device.UCameraDevice`."""

    def __init__(self, client: UCameraClient, settings: UCameraSettings,
                 axes: AxesRelease) -> None:
        self.client = client
        self.settings = settings
        self.axes = axes
        #: the vehicle attitude last sent to the gimbal (~/ext/imu) and when (time.time())
        self.vehicle_attitude: tuple[Attitude, float] | None = None

    # ------------------------------------------------------------------ extras
    def mode(self) -> str:
        mode = self.client.state().mode
        return mode_name(mode) if mode is not None else ""

    def set_mode(self, name: str) -> str:
        """Select a mode by name; answer once the gimbal reports it (``mode_timeout``)."""
        key = name.strip().lower()
        if key not in MODE_NAMES:
            raise InvalidRequest(
                f"unknown mode {name!r}; the U-Camera modes are " + ", ".join(MODE_NAMES))
        mode = MODE_NAMES[key]
        client = self.client
        if mode == GimbalMode.FFC_CALIBRATION and client.state().gimbal_type == GimbalType.DAYLIGHT:
            raise DeviceRefused("ffc_calibration needs an IR gimbal; this one is daylight")
        self.command_mode(mode)
        deadline = time.monotonic() + self.settings.mode_timeout
        while time.monotonic() < deadline:
            if client.state().mode == mode:
                suffix = (" (returns to angles by itself when done)"
                          if mode in SELF_ENDING_MODES else "")
                return f"mode {key} active{suffix}"
            time.sleep(0.02)
        reported = client.state().mode
        raise DeviceTimeout(
            f"device did not report mode {key} within {self.settings.mode_timeout:g} s "
            f"(reports {mode_name(reported) if reported is not None else 'nothing'})")

    def command_mode(self, mode: GimbalMode) -> None:
        """Hand the axes to a device mode: the driver's set-point, ramp and jog end here.

        ``angles`` holds the current position and ``rates`` starts with zero rates.
        """
        client = self.client

        def hand_over() -> None:
            if mode == GimbalMode.ANGLES:
                client.hold_angles()
            elif mode == GimbalMode.RATES:
                client.set_rates(0.0, 0.0)
            else:
                client.set_mode(mode)

        self.axes.release_axes(hand_over)

    def set_telemetry_rate(self, rate: int) -> None:
        """Send a new report rate now (volatile); refused when the gimbal reports another."""
        if not self.client.connected or rate == 0:
            return  # applied when the link opens
        achieved = self.client.commands.set_telemetry_rate(rate)
        if achieved != rate:
            raise DeviceRefused(f"the gimbal reports {achieved} Hz")

    def set_refresh_rate(self, rate: float) -> None:
        self.client.refresh_period = 1.0 / rate

    def set_zoom(self, level: float) -> None:
        """Zoom 0 (wide) .. 1 (tele)."""
        self.client.commands.set_zoom(level)

    def set_ir_palette(self, palette: int) -> None:
        self.client.commands.set_ir_palette(palette)

    def send_external_velocity(self, east: float, north: float, up: float) -> None:
        """ENU ground velocity (m/s) -> the gimbal's NED GPS velocities."""
        self.client.commands.send_gps_velocity(north, east, -up)

    def send_external_fix(self, latitude: float, longitude: float, altitude: float,
                          east: float, north: float, up: float) -> None:
        """A fix (degrees, m) with its ENU velocity -> Send GPS Position and Velocities."""
        self.client.commands.send_gps(latitude, longitude, altitude, north, east, -up)

    def send_external_attitude(self, x: float, y: float, z: float, w: float) -> None:
        """Vehicle orientation quaternion (ENU world, FLU body) -> Send Vehicle Angles."""
        norm = math.sqrt(x * x + y * y + z * z + w * w)
        if not 0.9 < norm < 1.1:
            raise InvalidRequest(f"quaternion norm {norm:.3f} is not 1")
        rep103 = euler_from_quaternion(x / norm, y / norm, z / norm, w / norm)
        yaw, pitch, roll = enu_flu_to_ned_frd(*rep103)
        self.client.commands.send_vehicle_angles(yaw, pitch, roll)
        self.vehicle_attitude = (Attitude(*rep103), time.time())

    def send_external_body_rates(self, x: float, y: float, z: float) -> None:
        """FLU body rates (rad/s) -> FRD p, q, r -> Send Vehicle Angular Velocities."""
        self.client.commands.send_vehicle_rates(-z, -y, x)

    def save_configuration(self) -> str:
        self._check_nv_allowed("save_configuration")
        self.client.commands.save_configuration()
        return "configuration saved to non-volatile memory (the gimbal is silent for about 1 s)"

    def save_ffc(self) -> str:
        self._check_nv_allowed("save_ffc")
        if self.client.state().gimbal_type != GimbalType.IR:
            raise DeviceRefused("save_ffc needs an IR gimbal")
        self.client.commands.save_ffc()
        return "FFC calibration saved to the IR module (may take up to 10 s)"

    def _check_nv_allowed(self, what: str) -> None:
        if not self.settings.allow_nv_write:
            raise DeviceRefused(
                f"{what} refused: non-volatile writes need the parameter allow_nv_write:=true "
                "(never during flight; keep the power stable while saving)")
