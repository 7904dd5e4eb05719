"""The U-Camera's capability objects (no ROS): where the vehicle is and how it lies
(:class:`UCameraGeolocation`), homing by the gimbal's pilot mode (:class:`PilotHoming`) and
the status report (:class:`UCameraStatus`). Each wraps the :class:`~.device.UCameraDevice`
it serves.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from gimbal_driver_common.device import Geolocation, Homing, StatusReport
from gimbal_driver_common.diagnostics import Level, StatusPart
from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout
from gimbal_driver_common.geodesy import DevicePose, GeoPoint, OrientationFix, PositionFix

from .protocol import GimbalMode, GimbalType, mode_name

if TYPE_CHECKING:
    from .device import UCameraDevice


class UCameraGeolocation(Geolocation):
    """Where the vehicle is and how it lies. Pan and tilt turn relative to the vehicle body
    (the gimbal fixed frame, 4.3.1), so the base frame is the body: its attitude in ENU is
    the one ~/ext/imu gave (the same angles the gimbal is sent, Send Vehicle Angles 5.5.5.5;
    UCSP has no report of the attitude the gimbal estimates itself). The position is the
    System Position Report (5.5.5.3, the gimbal's own solution, which follows the external
    feed when that is configured); its altitude is taken as height above the WGS84
    ellipsoid, as in the NavSatFix the feed sends (the manual names no datum)."""

    POSITION_SOURCE = "System Position Report"
    ORIENTATION_SOURCE = "~/ext/imu (vehicle attitude sent to the gimbal)"

    def __init__(self, device: UCameraDevice) -> None:
        self.device = device

    def pose(self) -> DevicePose:
        state = self.device.client.state()
        missing: dict[str, str] = {}
        position = orientation = None
        if state.latitude is None or state.longitude is None or state.altitude is None:
            missing["position"] = "no System Position Report received from the gimbal"
        else:
            position = PositionFix(GeoPoint(state.latitude, state.longitude, state.altitude),
                                   self.POSITION_SOURCE, stamp=state.position_time)
        attitude = self.device.functions.vehicle_attitude
        if attitude is None:
            missing["orientation"] = (
                "the U-Camera reports no vehicle attitude: publish it as sensor_msgs/Imu on "
                "~/ext/imu")
        else:
            orientation = OrientationFix(attitude[0], self.ORIENTATION_SOURCE, stamp=attitude[1])
        return DevicePose(position, orientation, missing)


class PilotHoming(Homing):
    """``~/home``: pilot mode, the gimbal points to pan 0 / tilt 0 (front view, 4.2)."""

    def __init__(self, device: UCameraDevice) -> None:
        self.device = device

    def home(self, joints: Sequence[str], report: Callable[[str], None],
             cancelled: threading.Event) -> str:
        device, client = self.device, self.device.client
        device.functions.command_mode(GimbalMode.PILOT)
        report("pilot mode requested")
        timeout = device.settings.home_timeout
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if cancelled.is_set():  # the caller stops the gimbal on a cancel
                raise DeviceRefused("homing cancelled")
            state = client.state()
            tolerance = device.tolerance()
            at_zero = (state.pan is not None and state.tilt is not None
                       and abs(state.pan) <= tolerance and abs(state.tilt) <= tolerance)
            if state.mode == GimbalMode.PILOT and at_zero:
                return "pilot position reached (pan 0, tilt 0); device stays in pilot mode"
            report(f"mode {mode_name(state.mode) if state.mode is not None else '?'}, "
                   "going to pan 0 / tilt 0")
            time.sleep(0.05)
        raise DeviceTimeout(f"pilot position not reached within home_timeout {timeout:g} s "
                            f"(device mode {mode_name(client.state().mode or 0)})")


class UCameraStatus(StatusReport):
    """Mode, link counters and telemetry rate for /diagnostics and ~/status."""

    def __init__(self, device: UCameraDevice) -> None:
        self.device = device
        self._last_checksum_errors = 0

    def mode(self) -> str:
        return self.device.functions.mode()

    def errors(self) -> list[str]:
        error = self.device.client.mode_error
        return [error] if error else []

    def axis_details(self, joint: str) -> dict[str, object]:
        return {"calibrated": True, "homed": False}

    def parts(self) -> list[StatusPart]:
        device, client, settings = self.device, self.device.client, self.device.settings
        state = client.state()
        stats = client.stats
        achieved = client.telemetry_rate_achieved()
        new_errors = max(0, stats.checksum_errors - self._last_checksum_errors)
        self._last_checksum_errors = stats.checksum_errors
        mode = device.functions.mode()
        level, message = Level.OK, f"mode {mode or '?'}"
        if settings.telemetry_rate and achieved < 0.7 * settings.telemetry_rate:
            level = Level.WARN
            message += f"; telemetry {achieved:.1f} Hz of {settings.telemetry_rate} Hz"
        if new_errors:
            level = Level.WARN
            message += f"; {new_errors} checksum error(s) since last report"
        missing = device.unanswered.summary()
        if missing:  # best-effort connect-time reads: the node works without them
            level = max(level, Level.WARN)
            message += f"; {missing}"
        pending = client.pending_automatic_mode
        antenna = device.antenna
        values = [
            ("mode", mode),
            ("automatic_mode_pending", mode_name(pending) if pending is not None else ""),
            ("gimbal_type", GimbalType(state.gimbal_type).name.lower()
             if state.gimbal_type in set(GimbalType) else str(state.gimbal_type)),
            ("telemetry_rate_configured_hz", str(settings.telemetry_rate or "device default")),
            ("telemetry_rate_achieved_hz", f"{achieved:.2f}"),
            ("checksum_errors", str(stats.checksum_errors)),
            ("length_errors", str(stats.length_errors)),
            ("discarded_bytes", str(stats.discarded_bytes)),
            ("unknown_packets", str(stats.unknown_packets)),
            ("bad_payloads", str(stats.bad_payloads)),
            ("silences", str(stats.silences)),
            ("link_reopens", str(stats.reconnects)),
            ("last_error", client.last_error),
            ("zoom", "" if state.zoom is None else f"{state.zoom:.4f}"),
            ("ir_palette", "" if state.ir_palette is None else str(state.ir_palette)),
            ("antenna_position_m", "" if antenna is None
             else ", ".join(f"{v:.3f}" for v in antenna)),
            ("nv_write_allowed", str(settings.allow_nv_write)),
            *device.unanswered.diagnostics(),
        ]
        parts = [StatusPart("device", level, message, values)]
        positions = device.from_device(state.pan or 0.0, state.tilt or 0.0)
        rates = device.from_device(state.pan_rate or 0.0, state.tilt_rate or 0.0)
        for name in device.joint_names:
            parts.append(StatusPart(name, Level.OK, "OK", [
                ("position_rad", f"{positions[name]:.5f}"),
                ("velocity_rad_s", f"{rates[name]:.5f}"),
            ]))
        return parts
