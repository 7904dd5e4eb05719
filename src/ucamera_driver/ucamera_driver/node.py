"""ROS 2 node for the U-Camera: a thin layer over :class:`UCameraClient`.

The shared :class:`GimbalDriverNode` provides the lifecycle, joint_states,
joint_command, the jog watchdog, ~/stop, ~/move_to, ~/home, presets, scans,
/diagnostics and ~/status. This node adds the U-Camera hooks and extras:

* ``~/set_mode`` (gimbal_msgs/SetMode) for every device mode;
* ``~/zoom`` (std_msgs/Float64, 0 wide .. 1 tele) and ``~/zoom_command``;
* ``~/fix`` (sensor_msgs/NavSatFix) from the System Position Report;
* ``~/ir_palette`` (std_msgs/UInt16) and ``~/ir_palette_command``;
* external feed: ``~/ext/fix`` (NavSatFix), ``~/ext/velocity``
  (geometry_msgs/TwistStamped, ENU) and ``~/ext/imu`` (sensor_msgs/Imu, ENU/FLU)
  forwarded to the gimbal in its NED/FRD units;
* ``~/save_configuration`` and ``~/save_ffc`` (std_srvs/Trigger), refused unless
  ``allow_nv_write`` is true.

Frames: the gimbal fixed frame of the manual (4.3.1) is X forward, Z down the
pan axis toward the camera, so Y points right; positive device pan turns right
and positive device tilt raises the camera. REP-103 wants positive pan to the
left, so pan is negated (``invert_pan``, default true) and tilt is kept.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence

from geometry_msgs.msg import TwistStamped
from rclpy.callback_groups import ReentrantCallbackGroup
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus
from std_msgs.msg import Float64, UInt16
from std_srvs.srv import Trigger

from gimbal_driver_common.device import DeviceInfo, JointSample
from gimbal_driver_common.diagnostics import Level
from gimbal_driver_common.ros.diagnostics import StatusPart
from gimbal_driver_common.ros.legacy import DeviceError
from gimbal_driver_common.ros.legacy import HookedDriverNode as GimbalDriverNode
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_driver_common.ros.run import run_driver
from gimbal_msgs.srv import SetMode

from .client import UCameraClient, UCameraError
from .protocol import (
    MODE_NAMES,
    AnglesReport,
    GimbalMode,
    GimbalType,
    GpsFeed,
    IrPaletteReport,
    Packet,
    ProtocolError,
    SystemPositionReport,
    ZoomReport,
    mode_name,
)

NODE_NAME = "ucamera_driver"
MOVING_RATE = math.radians(0.5)  # rad/s: reported rate above which an axis counts as moving


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


def quaternion_to_euler(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """ZYX Euler angles (roll, pitch, yaw) of a unit quaternion."""
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def enu_flu_to_ned_frd(roll: float, pitch: float, yaw: float) -> tuple[float, float, float]:
    """REP-103 attitude (ENU world, FLU body) -> aerospace yaw, pitch, roll (NED/FRD).

    Roll keeps its sign, pitch flips (FLU nose-down positive, FRD nose-up
    positive) and yaw turns from "east, counter-clockwise" to "north, clockwise".
    """
    return _wrap(math.pi / 2 - yaw), -pitch, roll


class RateLimiter:
    """Lets an event through at most ``rate`` times per second (0 = unlimited)."""

    def __init__(self, rate: float) -> None:
        self.period = 1.0 / rate if rate > 0 else 0.0
        self._last: dict[str, float] = {}
        self._lock = threading.Lock()

    def allow(self, key: str, now: float | None = None) -> bool:
        now = time.monotonic() if now is None else now
        with self._lock:
            if now - self._last.get(key, -math.inf) < self.period:
                return False
            self._last[key] = now
            return True


def _with_motion_lock(method):
    """Serialise the motion hooks (executor threads, ramp timer, watchdog)."""

    def wrapper(self, *args, **kwargs):
        with self._motion_lock:
            return method(self, *args, **kwargs)

    wrapper.__name__ = method.__name__
    wrapper.__doc__ = method.__doc__
    return wrapper


class UCameraDriverNode(GimbalDriverNode):
    """U-Camera driver (UCSP over RS-232)."""

    DEFAULT_JOINT_NAMES = ("pan", "tilt")
    STREAMED = True  # angles arrive as periodic reports; publish each as it comes
    DEFAULT_POSITION_MIN = (-math.pi, -math.pi / 2)
    DEFAULT_POSITION_MAX = (math.pi, math.pi / 2)
    DEFAULT_VELOCITY_MAX = (1.0, 1.0)

    def __init__(self, **kwargs: object) -> None:
        self.client: UCameraClient | None = None
        self._client_lock = threading.RLock()
        self._motion_lock = threading.RLock()  # setpoint/ramp/jog state (several threads)
        self._setpoint: dict[str, float] = {}
        self._ramp: dict[str, tuple[float, float]] = {}  # joint -> (target, speed)
        self._jog_rates: dict[str, float] = {}
        self._last_angles_time = 0.0
        self._last_checksum_errors = 0
        self._antenna: tuple[float, ...] | None = None
        self._ext_velocity: tuple[float, float, float, float] | None = None  # n, e, d, time
        super().__init__(NODE_NAME, **kwargs)
        if len(self.joint_names) != 2:
            raise ParameterError(
                f"parameter joint_names: the U-Camera has two joints (pan, tilt), got "
                f"{self.joint_names}"
            )
        if self.telemetry_rate and self.publish_rate > self.telemetry_rate:
            self.get_logger().warning(
                f"publish_rate {self.publish_rate:g} Hz > telemetry_rate {self.telemetry_rate} "
                "Hz: joint_states are published when a new angles report arrives, so they "
                "come at the telemetry rate")
        self._feed_limiter = RateLimiter(self.external_feed_rate)
        self._report_limiter = RateLimiter(self.report_publish_rate)
        self._zoom_pub = self.create_publisher(Float64, "~/zoom", 10)
        self._fix_pub = self.create_publisher(NavSatFix, "~/fix", 10)
        self._palette_pub = self.create_publisher(UInt16, "~/ir_palette", 10)
        group = ReentrantCallbackGroup()  # own group: services may wait on the device
        self.create_service(SetMode, "~/set_mode", self._on_set_mode, callback_group=group)
        self.create_service(Trigger, "~/save_configuration", self._on_save_configuration,
                            callback_group=group)
        self.create_service(Trigger, "~/save_ffc", self._on_save_ffc, callback_group=group)
        self.create_subscription(Float64, "~/zoom_command", self._on_zoom_command, 1,
                                 callback_group=group)
        self.create_subscription(UInt16, "~/ir_palette_command", self._on_palette_command, 1,
                                 callback_group=group)
        self.create_subscription(NavSatFix, "~/ext/fix", self._on_ext_fix, 5,
                                 callback_group=group)
        self.create_subscription(TwistStamped, "~/ext/velocity", self._on_ext_velocity, 5,
                                 callback_group=group)
        self.create_subscription(Imu, "~/ext/imu", self._on_ext_imu, 5, callback_group=group)
        self.add_periodic(0.05, self._step_ramp)

    # ------------------------------------------------------------ parameters
    def declare_device_parameters(self) -> None:
        self.serial_port = self.declare_param(
            "serial_port", "/dev/ttyUSB0", "serial device of the U-Camera RS-232 link")
        self.baudrate = self.declare_param(
            "baudrate", 115200, "serial speed (UCSP: 115200 8N1)", value_range=(1200, 4000000))
        self.telemetry_rate = self.declare_param(
            "telemetry_rate", 50, "periodic report rate set at connect, Hz (1..200; 0 = keep "
            "the device setting)", value_range=(0, 200))
        self.refresh_rate = self.declare_param(
            "refresh_rate", 10.0, "Hz at which mode and angles/rates are re-sent (manual: "
            ">= 10 Hz)", value_range=(1.0, 100.0))
        self.silence_timeout = self.declare_param(
            "silence_timeout", 1.5, "s without any valid packet before the link is reopened",
            value_range=(0.1, 60.0))
        self.request_timeout = self.declare_param(
            "request_timeout", 0.5, "s to wait for the answer to a request",
            value_range=(0.05, 10.0))
        self.connect_timeout = self.declare_param(
            "connect_timeout", 3.0, "s to wait for the version answer at configure",
            value_range=(0.2, 60.0))
        self.mode_timeout = self.declare_param(
            "mode_timeout", 3.0, "s ~/set_mode and ~/home wait for the device to report "
            "the mode", value_range=(0.1, 60.0))
        self.home_timeout = self.declare_param(
            "home_timeout", 20.0, "s ~/home waits to reach the pilot position",
            value_range=(0.5, 600.0))
        self.invert_pan = self.declare_param(
            "invert_pan", True, "negate pan between device (positive right) and ROS "
            "(REP-103: positive left)", read_only=True)
        self.invert_tilt = self.declare_param(
            "invert_tilt", False, "negate tilt between device and ROS (positive raises)",
            read_only=True)
        self.gps_feed = self.declare_param(
            "gps_feed", "", "GPS source set at connect: internal, external or '' (keep)",
            choices=["", "internal", "external"])
        self.antenna_position = self.declare_param(
            "antenna_position", [0.0], "GPS antenna x, y, z in the gimbal fixed frame, m, set "
            "at connect ([0.0] alone = keep the device value)", value_range=(-32.767, 32.767))
        if len(self.antenna_position) not in (1, 3):
            raise ParameterError("parameter 'antenna_position': give x, y, z in metres")
        self.ir_palette = self.declare_param(
            "ir_palette", -1, "IR palette set at connect (-1 = keep)", value_range=(-1, 65535))
        self.external_feed_rate = self.declare_param(
            "external_feed_rate", 20.0, "max Hz at which each ~/ext/* input is forwarded "
            "(0 = every message; the serial link carries ~11 kB/s)", value_range=(0.0, 200.0))
        self.external_velocity_max_age = self.declare_param(
            "external_velocity_max_age", 1.0, "s: a ~/ext/fix is forwarded with the last "
            "~/ext/velocity only if that is this fresh", value_range=(0.01, 60.0))
        self.report_publish_rate = self.declare_param(
            "report_publish_rate", 10.0, "max Hz of ~/zoom, ~/fix and ~/ir_palette (0 = every "
            "report, i.e. the telemetry rate)", value_range=(0.0, 200.0))
        self.frame_id = self.declare_param(
            "frame_id", "ucamera", "frame_id of ~/fix")
        self.allow_nv_write = self.declare_param(
            "allow_nv_write", False, "opt-in for ~/save_configuration and ~/save_ffc "
            "(non-volatile memory writes; never in flight)", read_only=True)

    # ------------------------------------------------- run-time parameters
    def declare_runtime_parameters(self) -> None:
        """U-Camera parameters that apply when set: telemetry rate, refresh, limits of the
        forwarded feeds and reports, timeouts, frame id.

        ``telemetry_rate`` is sent to the gimbal at once while connected (volatile, like at
        connect; 0 keeps the device setting) and refused when the gimbal reports another
        rate. The serial link, axis signs, GPS feed/antenna/palette set at connect and the
        non-volatile opt-in need a reconfigure (or are read-only).
        """

        def send_telemetry_rate(rate: int) -> None:
            with self._client_lock:
                client = self.client
            if client is None or not client.connected or rate == 0:
                return  # applied when the link opens (_configure_device)
            achieved = client.set_telemetry_rate(rate)
            if achieved != rate:
                raise DeviceError(f"the gimbal reports {achieved} Hz")

        def set_refresh_rate(rate: float) -> None:
            self.refresh_rate = rate
            with self._client_lock:
                if self.client is not None:
                    self.client.refresh_period = 1.0 / rate

        def set_feed_rate(rate: float) -> None:
            self.external_feed_rate = rate
            self._feed_limiter = RateLimiter(rate)

        def set_report_rate(rate: float) -> None:
            self.report_publish_rate = rate
            self._report_limiter = RateLimiter(rate)

        self.runtime_parameter("telemetry_rate", "telemetry_rate", send=send_telemetry_rate)
        self.runtime_parameter("refresh_rate", set_refresh_rate)
        self.runtime_parameter("external_feed_rate", set_feed_rate)
        self.runtime_parameter("report_publish_rate", set_report_rate)
        for name in ("mode_timeout", "home_timeout", "external_velocity_max_age", "frame_id"):
            self.runtime_parameter(name, name)

    # ---------------------------------------------------------------- frames
    def _signs(self) -> tuple[float, float]:
        return (-1.0 if self.invert_pan else 1.0, -1.0 if self.invert_tilt else 1.0)

    def _to_device(self, joint_values: dict[str, float]) -> tuple[float, float]:
        pan_name, tilt_name = self.joint_names
        sign_pan, sign_tilt = self._signs()
        return sign_pan * joint_values[pan_name], sign_tilt * joint_values[tilt_name]

    def _from_device(self, pan: float, tilt: float) -> dict[str, float]:
        sign_pan, sign_tilt = self._signs()
        return {self.joint_names[0]: sign_pan * pan, self.joint_names[1]: sign_tilt * tilt}

    def _require_client(self) -> UCameraClient:
        client = self.client
        if client is None:
            raise DeviceError("U-Camera link is not open")
        return client

    # ---------------------------------------------------------------- hooks
    def open_device(self) -> DeviceInfo:
        with self._client_lock:
            if self.client is not None:
                self.client.stop()
            client = UCameraClient(
                self.serial_port, self.baudrate, refresh_rate=self.refresh_rate,
                silence_timeout=self.silence_timeout, request_timeout=self.request_timeout,
                on_report=self._on_report,
            )
            try:
                version = client.start(timeout=self.connect_timeout)
                self._configure_device(client)
            except (UCameraError, ProtocolError) as exc:
                client.stop()
                raise DeviceError(str(exc)) from exc
            self.client = client
        with self._motion_lock:
            self._setpoint.clear()
            self._ramp.clear()
            self._jog_rates.clear()
        deadline = time.monotonic() + 1.0
        while client.state().gimbal_type is None and time.monotonic() < deadline:
            time.sleep(0.02)
        if client.state().mode == GimbalMode.RATES:
            # A jog may have been running when the link was lost: the gimbal keeps its
            # last rates, so stop it before anything else (safety on (re)connect).
            client.set_rates(0.0, 0.0)
            self.get_logger().warning("gimbal was in rates mode at connect: rates set to zero")
        gimbal_type = client.state().gimbal_type
        kind = GimbalType(gimbal_type).name.lower() if gimbal_type in set(GimbalType) else "?"
        return DeviceInfo(
            model=f"Airelectronics U-Camera ({kind})",
            serial_number=version.serial_number,
            firmware_version=version.firmware,
            hardware_id=f"ucamera-{version.serial_number}",
        )

    def _configure_device(self, client: UCameraClient) -> None:
        """Apply the connect-time settings (volatile until ~/save_configuration)."""
        if self.telemetry_rate:
            achieved = client.set_telemetry_rate(self.telemetry_rate)
            if achieved != self.telemetry_rate:
                self.get_logger().warning(
                    f"telemetry_rate {self.telemetry_rate} Hz requested, device reports "
                    f"{achieved} Hz")
        if self.gps_feed:
            client.configure_gps_feed(
                GpsFeed.EXTERNAL if self.gps_feed == "external" else GpsFeed.INTERNAL)
        if len(self.antenna_position) == 3:
            client.set_antenna_position(*self.antenna_position)
        if self.ir_palette >= 0:
            client.set_ir_palette(self.ir_palette)
        try:
            self._antenna = client.request_antenna_position()
        except UCameraError as exc:
            self.get_logger().warning(f"antenna position not read: {exc}")

    def close_device(self) -> None:
        with self._client_lock:
            client, self.client = self.client, None
        if client is not None:
            client.stop()

    def poll_device(self) -> JointSample | None:
        client = self._require_client()
        if not client.connected:  # the base node then closes and reopens via open_device
            raise DeviceError(f"U-Camera link down: {client.last_error or 'no telemetry'}")
        state = client.state()
        if state.pan is None or state.tilt is None or state.angles_time == self._last_angles_time:
            return None
        self._last_angles_time = state.angles_time
        positions = self._from_device(state.pan, state.tilt)
        velocities = self._from_device(state.pan_rate or 0.0, state.tilt_rate or 0.0)
        return JointSample(
            positions=positions, velocities=velocities, stamp=state.angles_time,
            moving={name: abs(v) > MOVING_RATE for name, v in velocities.items()},
        )

    @_with_motion_lock
    def send_moves(self, moves: dict[str, tuple[float, float | None]]) -> None:
        client = self._require_client()
        current = self.current_positions()
        for name in self.joint_names:
            if name not in self._setpoint:
                self._setpoint[name] = current.get(name, 0.0)
        self._jog_rates.clear()
        for name, (target, speed) in moves.items():
            if speed is None:
                self._ramp.pop(name, None)
                self._setpoint[name] = target
            else:
                # the device has no speed input: ramp the angle setpoint from where it is
                self._setpoint[name] = current.get(name, self._setpoint[name])
                self._ramp[name] = (target, speed)
        client.set_angles(*self._to_device(self._setpoint))

    @_with_motion_lock
    def _step_ramp(self) -> None:
        if not self._ramp or self.client is None or not self.connected:
            return
        dt = 0.05
        for name, (target, speed) in list(self._ramp.items()):
            error = target - self._setpoint[name]
            step = speed * dt
            if abs(error) <= step:
                self._setpoint[name] = target
                self._ramp.pop(name, None)
            else:
                self._setpoint[name] += math.copysign(step, error)
        try:
            self.client.set_angles(*self._to_device(self._setpoint))
        except (UCameraError, ProtocolError) as exc:
            self.get_logger().warning(f"move setpoint not sent: {exc}", throttle_duration_sec=2.0)

    @_with_motion_lock
    def send_jogs(self, jogs: dict[str, float]) -> None:
        client = self._require_client()
        self._ramp.clear()  # a jog replaces any ramped move (one mode for both axes)
        for name in self.joint_names:
            self._jog_rates.setdefault(name, 0.0)
        self._jog_rates.update(jogs)
        self._setpoint.clear()
        client.set_rates(*self._to_device(self._jog_rates))

    @_with_motion_lock
    def stop_axes(self, joints: Sequence[str] | None) -> None:
        client = self._require_client()
        if joints is not None and self._jog_rates and set(joints) != set(self.joint_names):
            for name in joints:  # expired jog of some joints: zero only those rates
                self._jog_rates[name] = 0.0
            client.set_rates(*self._to_device(self._jog_rates))
            return
        self._ramp.clear()
        self._jog_rates.clear()
        self._setpoint.clear()
        client.hold()

    def reset_faults(self) -> str:
        raise DeviceError("the U-Camera protocol (UCSP) has no fault-reset command")

    def home(self, joints: Sequence[str], report: Callable[[str], None],
             cancelled: threading.Event) -> str:
        """Pilot mode: the gimbal points to pan 0 / tilt 0 (front view, 4.2)."""
        client = self._require_client()
        with self._motion_lock:
            self._ramp.clear()
            self._jog_rates.clear()
            self._setpoint.clear()
            client.set_mode(GimbalMode.PILOT)
        report("pilot mode requested")
        deadline = time.monotonic() + self.home_timeout
        while time.monotonic() < deadline:
            if cancelled.is_set():
                client.hold()
                raise DeviceError("homing cancelled")
            state = client.state()
            at_zero = (state.pan is not None and state.tilt is not None
                       and abs(state.pan) <= self.goal_tolerance
                       and abs(state.tilt) <= self.goal_tolerance)
            if state.mode == GimbalMode.PILOT and at_zero:
                return "pilot position reached (pan 0, tilt 0); device stays in pilot mode"
            report(f"mode {mode_name(state.mode) if state.mode is not None else '?'}, "
                   "going to pan 0 / tilt 0")
            time.sleep(0.05)
        raise DeviceError(f"pilot position not reached within home_timeout {self.home_timeout:g}"
                          f" s (device mode {mode_name(client.state().mode or 0)})")

    def device_mode(self) -> str:
        client = self.client
        mode = client.state().mode if client is not None else None
        return mode_name(mode) if mode is not None else ""

    def device_errors(self) -> list[str]:
        client = self.client
        if client is None:
            return []
        return [client.mode_error] if client.mode_error else []

    def link_description(self) -> str:
        return f"serial://{self.serial_port}?baudrate={self.baudrate}"

    def axis_details(self, joint: str) -> dict[str, object]:
        return {"calibrated": True, "homed": False}

    def device_status_parts(self) -> list[StatusPart]:
        client = self.client
        if client is None:
            return []
        state = client.state()
        stats = client.stats
        achieved = client.telemetry_rate_achieved()
        # a reconnect starts a new client whose counters restart at zero
        new_errors = max(0, stats.checksum_errors - self._last_checksum_errors)
        self._last_checksum_errors = stats.checksum_errors
        level, message = Level.OK, f"mode {self.device_mode() or '?'}"
        if self.telemetry_rate and achieved < 0.7 * self.telemetry_rate:
            level = Level.WARN
            message += f"; telemetry {achieved:.1f} Hz of {self.telemetry_rate} Hz"
        if new_errors:
            level = Level.WARN
            message += f"; {new_errors} checksum error(s) since last report"
        pending = client.pending_automatic_mode
        values = [
            ("mode", self.device_mode()),
            ("automatic_mode_pending", mode_name(pending) if pending is not None else ""),
            ("gimbal_type", GimbalType(state.gimbal_type).name.lower()
             if state.gimbal_type in set(GimbalType) else str(state.gimbal_type)),
            ("telemetry_rate_configured_hz", str(self.telemetry_rate or "device default")),
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
            ("antenna_position_m", "" if self._antenna is None
             else ", ".join(f"{v:.3f}" for v in self._antenna)),
            ("nv_write_allowed", str(self.allow_nv_write)),
        ]
        parts = [StatusPart("device", level, message, values)]
        positions = self._from_device(state.pan or 0.0, state.tilt or 0.0)
        rates = self._from_device(state.pan_rate or 0.0, state.tilt_rate or 0.0)
        for name in self.joint_names:
            parts.append(StatusPart(name, Level.OK, "OK", [
                ("position_rad", f"{positions[name]:.5f}"),
                ("velocity_rad_s", f"{rates[name]:.5f}"),
            ]))
        return parts

    # ------------------------------------------------------ reports -> topics
    def _on_report(self, packet: Packet, stamp: float) -> None:
        """Runs on the client's I/O thread for every received packet."""
        if isinstance(packet, AnglesReport):
            self.notify_new_data()  # publish joint_states now, not at the next tick
        if not self.active or not self.context.ok():
            return
        if not self._report_limiter.allow(type(packet).__name__):
            return
        try:
            self._publish_report(packet, stamp)
        except Exception as exc:  # noqa: BLE001 - context shut down between check and publish
            if self.context.ok():
                self.get_logger().warning(f"report not published: {exc}",
                                          throttle_duration_sec=5.0)

    def _publish_report(self, packet: Packet, stamp: float) -> None:
        if isinstance(packet, ZoomReport):
            self._zoom_pub.publish(Float64(data=packet.level))
        elif isinstance(packet, IrPaletteReport):
            self._palette_pub.publish(UInt16(data=packet.palette))
        elif isinstance(packet, SystemPositionReport):
            fix = NavSatFix()
            sec = math.floor(stamp)
            fix.header.stamp.sec = int(sec)
            fix.header.stamp.nanosec = int((stamp - sec) * 1e9)
            fix.header.frame_id = self.frame_id
            fix.status.status = NavSatStatus.STATUS_FIX
            fix.status.service = NavSatStatus.SERVICE_GPS
            fix.latitude = packet.latitude
            fix.longitude = packet.longitude
            fix.altitude = packet.altitude
            fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
            self._fix_pub.publish(fix)

    # -------------------------------------------------------------- services
    def _on_set_mode(self, request: SetMode.Request, response: SetMode.Response):
        def action() -> str:
            name = request.mode.strip().lower()
            if name not in MODE_NAMES:
                raise DeviceError(
                    f"unknown mode {request.mode!r}; the U-Camera modes are "
                    + ", ".join(MODE_NAMES))
            mode = MODE_NAMES[name]
            client = self._require_client()
            if (mode == GimbalMode.FFC_CALIBRATION
                    and client.state().gimbal_type == GimbalType.DAYLIGHT):
                raise DeviceError("ffc_calibration needs an IR gimbal; this one is daylight")
            with self._motion_lock:
                self._ramp.clear()
                self._jog_rates.clear()
                self._setpoint.clear()
                if mode == GimbalMode.ANGLES:
                    client.hold_angles()  # angles mode holding the current position
                elif mode == GimbalMode.RATES:
                    client.set_rates(0.0, 0.0)
                else:
                    client.set_mode(mode)
            deadline = time.monotonic() + self.mode_timeout
            while time.monotonic() < deadline:
                if client.state().mode == mode:
                    suffix = (" (returns to angles by itself when done)"
                              if mode in (GimbalMode.GYRO_AUTOALIGN, GimbalMode.FULL_AUTOALIGN,
                                          GimbalMode.FFC_CALIBRATION, GimbalMode.INIT) else "")
                    return f"mode {name} active{suffix}"
                time.sleep(0.02)
            reported = client.state().mode
            raise DeviceError(
                f"device did not report mode {name} within {self.mode_timeout:g} s "
                f"(reports {mode_name(reported) if reported is not None else 'nothing'})")

        return self.serve_request(response, action)

    def _on_save_configuration(self, request, response):
        def action() -> str:
            self._check_nv_allowed("save_configuration")
            self._require_client().save_configuration()
            return ("configuration saved to non-volatile memory (the gimbal is silent for "
                    "about 1 s)")

        return self.serve_request(response, action)

    def _on_save_ffc(self, request, response):
        def action() -> str:
            self._check_nv_allowed("save_ffc")
            client = self._require_client()
            if client.state().gimbal_type != GimbalType.IR:
                raise DeviceError("save_ffc needs an IR gimbal")
            client.save_ffc()
            return "FFC calibration saved to the IR module (may take up to 10 s)"

        return self.serve_request(response, action)

    def _check_nv_allowed(self, what: str) -> None:
        if not self.allow_nv_write:
            raise DeviceError(
                f"{what} refused: non-volatile writes need the parameter allow_nv_write:=true "
                "(never during flight; keep the power stable while saving)")

    # ----------------------------------------------------------- subscribers
    def _command_refusal(self, what: str) -> bool:
        refusal = self.command_refusal()
        if refusal:
            self.get_logger().warning(f"{what} ignored: {refusal}", throttle_duration_sec=2.0)
        return bool(refusal)

    def _send_or_warn(self, what: str, send: Callable[[UCameraClient], None]) -> None:
        if self._command_refusal(what):
            return
        try:
            send(self._require_client())
        except (UCameraError, ProtocolError, DeviceError) as exc:
            self.get_logger().warning(f"{what} rejected, nothing sent: {exc}",
                                      throttle_duration_sec=2.0)

    def _on_zoom_command(self, msg: Float64) -> None:
        self._send_or_warn("zoom_command", lambda c: c.set_zoom(msg.data))

    def _on_palette_command(self, msg: UInt16) -> None:
        self._send_or_warn("ir_palette_command", lambda c: c.set_ir_palette(msg.data))

    def _on_ext_velocity(self, msg: TwistStamped) -> None:
        east, north, up = msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z
        self._ext_velocity = (north, east, -up, time.monotonic())
        if self._feed_limiter.allow("velocity"):
            self._send_or_warn("ext/velocity",
                               lambda c: c.send_gps_velocity(north, east, -up))

    def _on_ext_fix(self, msg: NavSatFix) -> None:
        if msg.status.status < NavSatStatus.STATUS_FIX:
            return  # no fix: nothing worth forwarding
        velocity = self._ext_velocity
        if velocity is None or time.monotonic() - velocity[3] > self.external_velocity_max_age:
            self.get_logger().warning(
                "ext/fix not forwarded: the gimbal packet needs a velocity too; publish "
                "geometry_msgs/TwistStamped (ENU) on ~/ext/velocity", throttle_duration_sec=5.0)
            return
        if self._feed_limiter.allow("fix"):
            self._send_or_warn("ext/fix", lambda c: c.send_gps(
                msg.latitude, msg.longitude, msg.altitude, *velocity[:3]))

    def _on_ext_imu(self, msg: Imu) -> None:
        if not self._feed_limiter.allow("imu"):
            return
        q = msg.orientation
        norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
        if msg.orientation_covariance[0] != -1.0 and not 0.9 < norm < 1.1:
            self.get_logger().warning(
                f"ext/imu orientation not forwarded: quaternion norm {norm:.3f} is not 1",
                throttle_duration_sec=5.0)
        elif msg.orientation_covariance[0] != -1.0:
            yaw, pitch, roll = enu_flu_to_ned_frd(
                *quaternion_to_euler(q.x / norm, q.y / norm, q.z / norm, q.w / norm))
            self._send_or_warn("ext/imu orientation",
                               lambda c: c.send_vehicle_angles(yaw, pitch, roll))
        if msg.angular_velocity_covariance[0] != -1.0:
            w = msg.angular_velocity  # FLU body rates -> FRD p, q, r
            p, q_rate, r = w.x, -w.y, -w.z
            self._send_or_warn("ext/imu angular velocity",
                               lambda c: c.send_vehicle_rates(r, q_rate, p))


def main(args: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.WARNING,
                        format="[%(levelname)s] [ucamera_driver.%(name)s]: %(message)s")
    return run_driver(UCameraDriverNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
