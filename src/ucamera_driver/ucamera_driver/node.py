"""ROS 2 node for the U-Camera: parameters, the device adapter and the ROS extras.

The shared :class:`GimbalDriverNode` runs the controller (lifecycle,
joint_states, joint_command, the jog watchdog, ~/stop, ~/move_to, ~/home,
presets, scans, /diagnostics, ~/status) around :class:`UCameraDevice`
(``device.py``, which owns every unit, sign and frame conversion). This node
declares the parameters, builds the adapter and adds the U-Camera extras:

* ``~/set_mode`` (gimbal_msgs/SetMode) for every device mode;
* ``~/zoom`` (std_msgs/Float64, 0 wide .. 1 tele) and ``~/zoom_command``;
* ``~/fix`` (sensor_msgs/NavSatFix) from the System Position Report;
* ``~/ir_palette`` (std_msgs/UInt16) and ``~/ir_palette_command``;
* external feed: ``~/ext/fix`` (NavSatFix), ``~/ext/velocity``
  (geometry_msgs/TwistStamped, ENU) and ``~/ext/imu`` (sensor_msgs/Imu, ENU/FLU)
  forwarded to the gimbal (the adapter turns them into its NED/FRD units);
* ``~/save_configuration`` and ``~/save_ffc`` (std_srvs/Trigger), refused unless
  ``allow_nv_write`` is true.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence

from geometry_msgs.msg import TwistStamped
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus
from std_msgs.msg import Float64, UInt16
from std_srvs.srv import Trigger

from gimbal_driver_common.device import Device
from gimbal_driver_common.errors import DeviceRefused, GimbalError
from gimbal_driver_common.ros.base_node import Answer, GimbalDriverNode
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_driver_common.ros.run import run_driver
from gimbal_msgs.srv import SetMode

from .device import UCameraDevice, UCameraSettings
from .device_functions import UCameraFunctions
from .protocol import IrPaletteReport, Packet, SystemPositionReport, ZoomReport

NODE_NAME = "ucamera_driver"


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


class UCameraDriverNode(GimbalDriverNode):
    """U-Camera driver (UCSP over RS-232)."""

    DEFAULT_JOINT_NAMES = ("pan", "tilt")
    DEFAULT_POSITION_MIN = (-math.pi, -math.pi / 2)
    DEFAULT_POSITION_MAX = (math.pi, math.pi / 2)
    DEFAULT_VELOCITY_MAX = (1.0, 1.0)

    def __init__(self, **kwargs: object) -> None:
        self.settings = UCameraSettings()
        self._ext_velocity: tuple[float, float, float, float] | None = None  # e, n, u, time
        super().__init__(NODE_NAME, **kwargs)
        if len(self.joint_names) != 2:
            raise ParameterError(
                f"parameter joint_names: the U-Camera has two joints (pan, tilt), got "
                f"{self.joint_names}"
            )
        pan, tilt = self.joint_names
        self.settings.joint_names = (pan, tilt)
        if self.settings.telemetry_rate and self.publish_rate > self.settings.telemetry_rate:
            self.get_logger().warning(
                f"publish_rate {self.publish_rate:g} Hz > telemetry_rate "
                f"{self.settings.telemetry_rate} Hz: joint_states are published when a new "
                "angles report arrives, so they come at the telemetry rate")
        self._feed_limiter = RateLimiter(self.external_feed_rate)
        self._report_limiter = RateLimiter(self.report_publish_rate)
        self._zoom_pub = self.create_publisher(Float64, "~/zoom", 10)
        self._fix_pub = self.create_publisher(NavSatFix, "~/fix", 10)
        self._palette_pub = self.create_publisher(UInt16, "~/ir_palette", 10)
        self.create_services([
            (SetMode, "~/set_mode", self._on_set_mode),
            (Trigger, "~/save_configuration", self._on_save_configuration),
            (Trigger, "~/save_ffc", self._on_save_ffc),
        ])
        group = self.service_group  # the inputs may wait on the device too
        self.create_subscription(Float64, "~/zoom_command", self._on_zoom_command, 1,
                                 callback_group=group)
        self.create_subscription(UInt16, "~/ir_palette_command", self._on_palette_command, 1,
                                 callback_group=group)
        self.create_subscription(NavSatFix, "~/ext/fix", self._on_ext_fix, 5,
                                 callback_group=group)
        self.create_subscription(TwistStamped, "~/ext/velocity", self._on_ext_velocity, 5,
                                 callback_group=group)
        self.create_subscription(Imu, "~/ext/imu", self._on_ext_imu, 5, callback_group=group)

    # ------------------------------------------------------------ parameters
    def declare_device_parameters(self) -> None:
        settings = self.settings
        settings.serial_port = self.declare_param(
            "serial_port", "/dev/ttyUSB0", "serial device of the U-Camera RS-232 link")
        settings.baudrate = self.declare_param(
            "baudrate", 115200, "serial speed (UCSP: 115200 8N1)", value_range=(1200, 4000000))
        settings.telemetry_rate = self.declare_param(
            "telemetry_rate", 50, "periodic report rate set at connect, Hz (1..200; 0 = keep "
            "the device setting)", value_range=(0, 200))
        settings.refresh_rate = self.declare_param(
            "refresh_rate", 10.0, "Hz at which mode and angles/rates are re-sent (manual: "
            ">= 10 Hz)", value_range=(1.0, 100.0))
        settings.silence_timeout = self.declare_param(
            "silence_timeout", 1.5, "s without any valid packet before the link is reopened",
            value_range=(0.1, 60.0))
        settings.request_timeout = self.declare_param(
            "request_timeout", 0.5, "s to wait for the answer to a request",
            value_range=(0.05, 10.0))
        settings.connect_timeout = self.declare_param(
            "connect_timeout", 3.0, "s to wait for the version answer at configure",
            value_range=(0.2, 60.0))
        settings.mode_timeout = self.declare_param(
            "mode_timeout", 3.0, "s ~/set_mode and ~/home wait for the device to report "
            "the mode", value_range=(0.1, 60.0))
        settings.home_timeout = self.declare_param(
            "home_timeout", 20.0, "s ~/home waits to reach the pilot position",
            value_range=(0.5, 600.0))
        settings.invert_pan = self.declare_param(
            "invert_pan", True, "negate pan between device (positive right) and ROS "
            "(REP-103: positive left)", read_only=True)
        settings.invert_tilt = self.declare_param(
            "invert_tilt", False, "negate tilt between device and ROS (positive raises)",
            read_only=True)
        settings.gps_feed = self.declare_param(
            "gps_feed", "", "GPS source set at connect: internal, external or '' (keep)",
            choices=["", "internal", "external"])
        settings.antenna_position = self.declare_param(
            "antenna_position", [0.0], "GPS antenna x, y, z in the gimbal fixed frame, m, set "
            "at connect ([0.0] alone = keep the device value)", value_range=(-32.767, 32.767))
        if len(settings.antenna_position) not in (1, 3):
            raise ParameterError("parameter 'antenna_position': give x, y, z in metres")
        settings.ir_palette = self.declare_param(
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
        settings.allow_nv_write = self.declare_param(
            "allow_nv_write", False, "opt-in for ~/save_configuration and ~/save_ffc "
            "(non-volatile memory writes; never in flight)", read_only=True)

    def declare_runtime_parameters(self) -> None:
        """U-Camera parameters that apply when set: telemetry rate, refresh, limits of the
        forwarded feeds and reports, timeouts, frame id.

        ``telemetry_rate`` is sent to the gimbal at once while connected (volatile, like at
        connect; 0 keeps the device setting) and refused when the gimbal reports another
        rate. The serial link, axis signs, GPS feed/antenna/palette set at connect and the
        non-volatile opt-in need a reconfigure (or are read-only).
        """

        def setting(name: str) -> Callable[[object], None]:
            return lambda value: setattr(self.settings, name, value)

        def send_telemetry_rate(rate: int) -> None:
            if self.device is not None:
                self._device_functions().set_telemetry_rate(rate)

        def set_refresh_rate(rate: float) -> None:
            self.settings.refresh_rate = rate
            if self.device is not None:
                self._device_functions().set_refresh_rate(rate)

        def set_feed_rate(rate: float) -> None:
            self.external_feed_rate = rate
            self._feed_limiter = RateLimiter(rate)

        def set_report_rate(rate: float) -> None:
            self.report_publish_rate = rate
            self._report_limiter = RateLimiter(rate)

        self.runtime_parameter("telemetry_rate", setting("telemetry_rate"),
                               send=send_telemetry_rate)
        self.runtime_parameter("refresh_rate", set_refresh_rate)
        self.runtime_parameter("external_feed_rate", set_feed_rate)
        self.runtime_parameter("report_publish_rate", set_report_rate)
        for name in ("mode_timeout", "home_timeout"):
            self.runtime_parameter(name, setting(name))
        for name in ("external_velocity_max_age", "frame_id"):
            self.runtime_parameter(name, name)

    def make_device(self) -> Device:
        return UCameraDevice(self.settings, tolerance=lambda: self.config.goal_tolerance,
                             on_report=self._on_report, log=self.get_logger())

    # ------------------------------------------------------ reports -> topics
    def _on_report(self, packet: Packet, stamp: float) -> None:
        """Runs on the client's reader thread for every received packet: zoom, palette and
        position reports become ~/zoom, ~/ir_palette and ~/fix while they have a
        subscriber, at most ``report_publish_rate``."""
        if not self.active or not self.context.ok():
            return
        if isinstance(packet, ZoomReport):
            publisher = self._zoom_pub
        elif isinstance(packet, IrPaletteReport):
            publisher = self._palette_pub
        elif isinstance(packet, SystemPositionReport):
            publisher = self._fix_pub
        else:
            return
        # nobody listening: no message is built (the reports keep coming either way)
        if not publisher.get_subscription_count():
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
    def _device_functions(self) -> UCameraFunctions:
        """The functions part of the adapter configure built (refused before)."""
        device = self.configured().device
        assert isinstance(device, UCameraDevice)
        return device.functions

    def _serve_device(self, response: Answer,
                      request: Callable[[UCameraFunctions], str]) -> Answer:
        """A service answered by the device's functions: refused while inactive, errors as
        success=false."""
        return self.serve_request(
            response, lambda: self.configured().call(lambda: request(self._device_functions())))

    def _on_set_mode(self, request: SetMode.Request, response: SetMode.Response):
        return self._serve_device(response, lambda device: device.set_mode(request.mode))

    def _on_save_configuration(self, request, response):
        return self._serve_device(response, lambda device: device.save_configuration())

    def _on_save_ffc(self, request, response):
        return self._serve_device(response, lambda device: device.save_ffc())

    # ----------------------------------------------------------- subscribers
    def _forward(self, what: str, send: Callable[[UCameraFunctions], None]) -> None:
        """Hand a topic message to the device; a refusal or bad value is logged, never raised."""
        try:
            self.configured().call(lambda: send(self._device_functions()))
        except DeviceRefused as exc:
            self.get_logger().warning(f"{what} ignored: {exc}", throttle_duration_sec=2.0)
        except GimbalError as exc:
            self.get_logger().warning(f"{what} rejected, nothing sent: {exc}",
                                      throttle_duration_sec=2.0)

    def _on_zoom_command(self, msg: Float64) -> None:
        self._forward("zoom_command", lambda device: device.set_zoom(msg.data))

    def _on_palette_command(self, msg: UInt16) -> None:
        self._forward("ir_palette_command", lambda device: device.set_ir_palette(msg.data))

    def _on_ext_velocity(self, msg: TwistStamped) -> None:
        linear = msg.twist.linear
        self._ext_velocity = (linear.x, linear.y, linear.z, time.monotonic())
        if self._feed_limiter.allow("velocity"):
            self._forward("ext/velocity", lambda device: device.send_external_velocity(
                linear.x, linear.y, linear.z))

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
            self._forward("ext/fix", lambda device: device.send_external_fix(
                msg.latitude, msg.longitude, msg.altitude, *velocity[:3]))

    def _on_ext_imu(self, msg: Imu) -> None:
        if not self._feed_limiter.allow("imu"):
            return
        if msg.orientation_covariance[0] != -1.0:
            q = msg.orientation
            self._forward("ext/imu orientation", lambda device: device.send_external_attitude(
                q.x, q.y, q.z, q.w))
        if msg.angular_velocity_covariance[0] != -1.0:
            w = msg.angular_velocity
            self._forward("ext/imu angular velocity",
                          lambda device: device.send_external_body_rates(w.x, w.y, w.z))


def main(args: Sequence[str] | None = None) -> int:
    return run_driver(UCameraDriverNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
