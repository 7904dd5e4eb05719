"""ROS 2 node for the CANaerospace turret: parameters, `TurretDevice` and the turret's extras.

The shared `GimbalDriverNode` and its controller own the lifecycle, the link supervisor,
joint_states, joint_command, the jog watchdog, ~/stop, ~/move_to, ~/home, presets (slot
0 is the turret's remember/restore position through `TurretPresets`, the rest YAML),
scans and /diagnostics. `TurretDevice` (device.py, no ROS) does every conversion and
decodes the status (status.py). This node declares the parameters, builds the device,
and adds the turret's own ROS interfaces: ~/set_actuator_mode, the cover, fan, heaters
and charging switches, ~/device_command (IDS, TIS, DUS and the opt-in NIS/FPS/DDS),
~/fix, ~/heading and ~/global_yaw (sensor_msgs/Imu), ~/time_reference, ~/inclination
and ~/zoom.

A turret node that stops sending (no frame for `node_timeout`) counts as a lost link:
the controller marks the device disconnected (ERROR in /diagnostics), stops publishing
joint_states and reconnects (IDS) every `reconnect_period` until frames resume.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus, TimeReference
from std_msgs.msg import Float64
from std_srvs.srv import SetBool

from gimbal_driver_common.device import Device
from gimbal_driver_common.errors import GimbalError
from gimbal_driver_common.ros.base_node import GimbalDriverNode
from gimbal_driver_common.ros.heading import heading_imu
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_driver_common.ros.run import run_driver
from gimbal_msgs.srv import DeviceCommand, SetMode

from .client import ClientConfig, TurretClient
from .device import MODE_NAMES, SWITCHES, TurretDevice, TurretSettings
from .protocol.identifiers import DATA_IDENTIFIERS, DEFAULT_ZOOM_POSITION_ID
from .readings import Heading
from .status import NODE_GROUPS

NODE_NAME = "canaero_turret_driver"
SENSOR_PERIOD_S = 0.1  # how often ~/fix, ~/heading, ... look for new frames


def _geoid_height(value: float) -> float | None:
    """The geoid_height parameter: None for NaN (unknown); the geoid lies within about
    -107..+86 m of the ellipsoid (EGM2008), so more than 200 m is a mistake."""
    if math.isnan(value):
        return None
    if not abs(value) <= 200.0:
        raise ParameterError(f"parameter 'geoid_height': {value} m is not a geoid height "
                             "(the geoid is within about -107..+86 m of the ellipsoid)")
    return float(value)


def _parse_options(items: Sequence[str]) -> dict[str, object]:
    """["key=value", ...] -> kwargs for can.Bus, with ints/floats/bools recognised."""
    options: dict[str, object] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ParameterError(f"parameter 'can_options': {item!r} is not key=value")
        value: object = text.strip()
        lowered = text.strip().lower()
        if lowered in ("true", "false"):
            value = lowered == "true"
        else:
            for kind in (int, float):
                try:
                    value = kind(text)
                    break
                except ValueError:
                    continue
        options[key.strip()] = value
    return options


def _parse_intervals(items: Sequence[str]) -> dict[str, int]:
    known = {ident.key for ident in DATA_IDENTIFIERS}
    intervals: dict[str, int] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or key not in known:
            raise ParameterError(
                f"parameter 'transmission_intervals': {item!r} must be <data key>=<ms> with a "
                f"key of the README's identifier table (e.g. yaw_position=20)")
        try:
            intervals[key] = int(text)
        except ValueError as exc:
            raise ParameterError(f"parameter 'transmission_intervals': {item!r}: the "
                                 "interval must be an integer number of ms") from exc
    return intervals


class CanaeroTurretNode(GimbalDriverNode):
    DEFAULT_JOINT_NAMES = ("yaw", "pitch")
    DEFAULT_POSITION_MIN = (-math.pi, math.radians(-30.0))
    DEFAULT_POSITION_MAX = (math.pi, math.radians(60.0))
    DEFAULT_VELOCITY_MAX = (math.radians(60.0), math.radians(40.0))

    def __init__(self) -> None:
        super().__init__(NODE_NAME)
        if len(self.joint_names) != 2:
            raise ParameterError("parameter 'joint_names': the turret has exactly two joints "
                                 "(yaw, pitch)")
        self._create_device_interfaces()

    # ------------------------------------------------------------------ parameters
    def declare_device_parameters(self) -> None:
        p = self.declare_param
        self.can_interface = p("can_interface", "socketcan",
                               "python-can interface name (socketcan, slcan, virtual, ...)")
        self.can_channel = p("can_channel", "can0", "python-can channel (can0, a tty, ...)")
        self.can_bitrate = p("can_bitrate", 0,
                             "bit/s passed to the interface; 0 = leave the interface as set "
                             "up (socketcan: ip link)", value_range=(0, 1_000_000))
        self.can_options = _parse_options([o for o in p(
            "can_options", [""], "extra python-can Bus arguments as key=value "
            "(e.g. sleep_after_open=0 for slcan)", element_type=str) if o])
        self.client_node_id = p("client_node_id", 100, "node-id this master sends with",
                                value_range=(1, 255))
        self.node_ids = {
            "turret_node_id": p("turret_node_id", 1, "turret node-id", value_range=(1, 255)),
            "cover_node_id": p("cover_node_id", 2, "cover node-id", value_range=(1, 255)),
            "rover_gnss_node_id": p("rover_gnss_node_id", 5, "rover GNSS node-id",
                                    value_range=(1, 255)),
            "base_gnss_node_id": p("base_gnss_node_id", 6, "base GNSS node-id",
                                   value_range=(1, 255)),
            "zoom_node_id": p("zoom_node_id", 7, "zoom node-id", value_range=(1, 255)),
        }
        self.zoom_position_id = p("zoom_position_id", DEFAULT_ZOOM_POSITION_ID,
                                  "CAN id of Camera0 zoom position (missing in the ICD)",
                                  value_range=(300, 1899))
        self.service_channel = p("service_channel", 0,
                                 "node service channel (0..35 high, 100..115 low priority)",
                                 value_range=(0, 115))
        if 35 < self.service_channel < 100:
            raise ParameterError("parameter 'service_channel': use 0..35 or 100..115")
        self.service_timeout = p("service_timeout", 0.1,
                                 "s to wait for a node-service response (ICD: 100 ms)",
                                 value_range=(0.01, 5.0))
        self.service_attempts = p("service_attempts", 3, "node-service attempts",
                                  value_range=(1, 10))
        self.stale_timeout = p("stale_timeout", 1.0,
                               "s without a data identifier before it is stale (WARN)",
                               value_range=(0.05, 600.0))
        self.node_timeout = p("node_timeout", 1.0,
                              "s without any frame from the turret while the node "
                              "listened before it is silent (link lost, ERROR)",
                              value_range=(0.05, 600.0))
        self.pad_frames = p("pad_frames", False, "send 8-byte frames (zero padded)")
        self.transfer_first_number = p(
            "transfer_first_number", 0, "number of the first DDS/DUS data message: 0 "
            "(libcanaerospace) or 1 (the ICD leaves it open)", value_range=(0, 1))
        self.yaw_direction = p("yaw_direction", 1, "+1 or -1: device yaw sign vs REP-103",
                               value_range=(-1, 1))
        self.pitch_direction = p("pitch_direction", 1,
                                 "+1 or -1: device pitch sign vs REP-103", value_range=(-1, 1))
        if 0 in (self.yaw_direction, self.pitch_direction):
            raise ParameterError("parameters 'yaw_direction'/'pitch_direction' must be +1 or -1")
        transmission_intervals = _parse_intervals([i for i in p(
            "transmission_intervals", [""], "TIS at configure: <data key>=<ms> "
            "(e.g. yaw_position=20); 0 stops an identifier", element_type=str) if i])
        request_intervals = p(
            "request_intervals", True, "TIS at every (re)connect: yaw/pitch position and "
            "velocity every 1/publish_rate (the turret's own default is slower)")
        actuator_mode = p("actuator_mode", "", "actuator mode set at activate "
                                    "(free_run, without_brake, auto_brake; '' = leave)")
        if actuator_mode and actuator_mode not in MODE_NAMES:
            raise ParameterError(f"parameter 'actuator_mode': {actuator_mode!r} is "
                                 f"not one of {sorted(MODE_NAMES)}")
        monitored_nodes = [n for n in p(
            "monitored_nodes", ["turret", "cover", "rover_gnss", "base_gnss", "zoom"],
            "nodes whose data identifiers are watched for staleness", element_type=str) if n]
        unknown = set(monitored_nodes) - set(NODE_GROUPS)
        if unknown:
            raise ParameterError(f"parameter 'monitored_nodes': unknown {sorted(unknown)}; "
                                 f"known: {sorted(NODE_GROUPS)}")
        temperature_warn = p("temperature_warn", 70.0, "degC: WARN above",
                                  value_range=(-50.0, 200.0))
        temperature_error = p("temperature_error", 85.0, "degC: ERROR above",
                                   value_range=(-50.0, 200.0))
        eed_hold = p("eed_hold_time", 10.0, "s an EED event keeps the events status WARN",
                          value_range=(0.0, 3600.0))
        geoid_height = p("geoid_height", math.nan,
                         "m, geoid height N at the site: ellipsoid height = the base GNSS's "
                         "mean-sea-level altitude + N, for ~/look_at_geo (NaN = unknown)")
        self.fix_frame_id = p("fix_frame_id", "gnss_base", "frame_id of ~/fix")
        self.inclination_frame_id = p("inclination_frame_id", "turret_base",
                                      "frame_id of ~/inclination")
        self.heading_frame_id = p("heading_frame_id", "gnss_rover",
                                  "frame_id of ~/heading and ~/global_yaw")
        self.allow_node_id_change = p("allow_node_id_change", False,
                                      "allow NIS (set_node_id) through ~/device_command")
        allow_data_download = p("allow_data_download", False,
                                     "allow DDS (download) through ~/device_command: it writes "
                                     "device memory")
        self.allow_flash_programming = p("allow_flash_programming", False,
                                         "allow FPS (store_configuration) through "
                                         "~/device_command")
        self.settings = TurretSettings(
            joint_names=tuple(self.joint_names), yaw_direction=self.yaw_direction,
            pitch_direction=self.pitch_direction, request_intervals=request_intervals,
            transmission_intervals=transmission_intervals, actuator_mode=actuator_mode,
            allow_data_download=allow_data_download, temperature_warn=temperature_warn,
            temperature_error=temperature_error, eed_hold=eed_hold,
            monitored_nodes=tuple(monitored_nodes), geoid_height=_geoid_height(geoid_height))

    # ------------------------------------------------------------------ run-time parameters
    def declare_runtime_parameters(self) -> None:
        """Turret parameters that apply when set: TIS intervals, thresholds, frame ids.

        ``transmission_intervals`` are checked like at start-up, sent to the turret at
        once while connected (a node-service refusal refuses the set with its reply) and
        kept for the next connect. The CAN link, node-ids and opt-ins need a reconfigure.
        """
        settings = self.settings

        def parse(items: Sequence[str]) -> dict[str, int]:
            return _parse_intervals([i for i in items if i])

        def send_intervals(items: Sequence[str]) -> None:
            device = self.device
            if device is None or not self.connected:
                return  # applied when the link opens (TurretDevice.open)
            self.configured().call(lambda: device.set_intervals(parse(items)))

        def set_intervals(items: Sequence[str]) -> None:
            settings.transmission_intervals = parse(items)

        def set_setting(name: str):
            return lambda value: setattr(settings, name, value)

        self.runtime_parameter("transmission_intervals", set_intervals, send=send_intervals,
                               check=parse)
        self.runtime_parameter("eed_hold_time", set_setting("eed_hold"))
        for name in ("temperature_warn", "temperature_error"):
            self.runtime_parameter(name, set_setting(name))
        for name in ("fix_frame_id", "inclination_frame_id"):
            self.runtime_parameter(name, name)
        self.runtime_parameter(
            "geoid_height", lambda value: setattr(settings, "geoid_height", _geoid_height(value)),
            check=_geoid_height)

    def _client_config(self) -> ClientConfig:
        return ClientConfig(
            interface=self.can_interface, channel=self.can_channel,
            bitrate=self.can_bitrate or None, bus_options=dict(self.can_options),
            client_node_id=self.client_node_id, zoom_position_id=self.zoom_position_id,
            service_channel=self.service_channel, service_timeout=self.service_timeout,
            service_attempts=self.service_attempts, stale_timeout=self.stale_timeout,
            node_timeout=self.node_timeout, pad_frames=self.pad_frames,
            allow_node_id_change=self.allow_node_id_change,
            allow_flash_programming=self.allow_flash_programming,
            transfer_first_number=self.transfer_first_number, **self.node_ids)

    # ------------------------------------------------------------------ device
    def make_device(self) -> Device:
        return TurretDevice(TurretClient(self._client_config()), self.settings,
                            lambda: self.config.publish_rate, self.get_logger())

    @property
    def device(self) -> TurretDevice | None:
        """The adapter make_device() built (after configure)."""
        device = super().device
        assert device is None or isinstance(device, TurretDevice)
        return device

    def _turret(self) -> TurretDevice:
        """The adapter, for a request path (refused before configure)."""
        device = self.configured().device
        assert isinstance(device, TurretDevice)
        return device

    def device_ready(self, device: Device) -> None:
        self.sensor_jobs.remove(self._publish_sensors)  # once, also after a reconfigure
        self.sensor_jobs.add(SENSOR_PERIOD_S, self._publish_sensors)

    def on_activate(self, state):
        result = super().on_activate(state)
        device = self.device
        if self.settings.actuator_mode and device is not None and self.connected:
            try:
                self.get_logger().info(self.configured().call(device.apply_actuator_mode))
            except GimbalError as exc:  # activation goes on, the log says why
                self.get_logger().error(f"setting actuator mode at activate failed: {exc}")
        return result

    # ------------------------------------------------------------------ services
    def _create_device_interfaces(self) -> None:
        self._fix_pub = self.create_publisher(NavSatFix, "~/fix", 10)
        self._heading_pub = self.create_publisher(Imu, "~/heading", 10)
        self._global_yaw_pub = self.create_publisher(Imu, "~/global_yaw", 10)
        self._time_pub = self.create_publisher(TimeReference, "~/time_reference", 10)
        self._inclination_pub = self.create_publisher(Vector3Stamped, "~/inclination", 10)
        self._zoom_pub = self.create_publisher(Float64, "~/zoom", 10)
        self.create_services([
            (SetMode, "~/set_actuator_mode", self._on_set_mode),
            *[(SetBool, f"~/{name}", self._switch_service(name)) for name in SWITCHES],
            (DeviceCommand, "~/device_command", self._on_device_command),
        ])

    def _on_set_mode(self, request, response):
        return self.serve_request(
            response, lambda: self.configured().call(
                lambda: self._turret().set_mode(request.mode)))

    def _switch_service(self, name: str):
        def callback(request, response):
            return self.serve_request(response, lambda: self.configured().call(
                lambda: self._turret().switch(name, bool(request.data))))

        return callback

    def _on_device_command(self, request: DeviceCommand.Request,
                           response: DeviceCommand.Response) -> DeviceCommand.Response:
        """See `TurretNodeServices.device_command`; NIS also moves this node to the new
        node-id."""
        results: list[str] = []

        def action() -> str:
            services = self._turret().node_services
            message, out = self.configured().call(
                lambda: services.device_command(request.command, list(request.arguments)))
            results.extend(out)
            self.node_ids.update(services.node_ids())  # a reconfigure keeps a new node-id
            return message

        response = self.serve_request(response, action)
        response.results = results
        return response

    # ------------------------------------------------------------------ topics
    def _publish_sensors(self) -> None:
        """Each sensor topic's newest frame, built only while the topic has a subscriber
        (the frames arrive anyway; building and publishing six messages ten times a
        second for nobody: skipping it took the housekeeping thread from 0.9 to 0.5 % of a
        core). The newest value waits for a subscriber that comes later."""
        device = self.device
        if device is None or not self.active or not self.connected:
            return
        fix = device.readings.new_fix() if self._fix_pub.get_subscription_count() else None
        if fix is not None:
            msg = NavSatFix()
            msg.header.stamp = self._stamp(fix.stamp)
            msg.header.frame_id = self.fix_frame_id
            msg.status.status = NavSatStatus.STATUS_FIX if fix.fresh \
                else NavSatStatus.STATUS_NO_FIX
            msg.status.service = NavSatStatus.SERVICE_GPS
            msg.latitude, msg.longitude, msg.altitude = fix.latitude, fix.longitude, fix.altitude
            if fix.accuracy is not None:
                variance = fix.accuracy ** 2
                msg.position_covariance = [variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0,
                                           variance]
                msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_APPROXIMATED
            else:
                msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
            self._fix_pub.publish(msg)
        for key, publisher in (("rover_heading", self._heading_pub),
                               ("global_yaw", self._global_yaw_pub)):
            if publisher.get_subscription_count():
                self._publish_heading(device.readings.new_heading(key), publisher)
        utc = device.readings.new_utc() if self._time_pub.get_subscription_count() else None
        if utc is not None:
            reference = TimeReference()
            reference.header.stamp = self._stamp(utc[0])
            reference.time_ref = self._stamp(utc[1])
            reference.source = "base_gnss"
            self._time_pub.publish(reference)
        inclination = (device.readings.inclination()
                       if self._inclination_pub.get_subscription_count() else None)
        if inclination is not None:
            msg = Vector3Stamped()
            msg.header.stamp = self._stamp(inclination.stamp)
            msg.header.frame_id = self.inclination_frame_id
            msg.vector.x, msg.vector.y = inclination.roll, inclination.pitch
            self._inclination_pub.publish(msg)
        zoom = device.readings.zoom() if self._zoom_pub.get_subscription_count() else None
        if zoom is not None:
            self._zoom_pub.publish(Float64(data=zoom))

    def _publish_heading(self, heading: Heading | None, publisher) -> None:
        """One new heading frame -> one Imu (ENU yaw, accuracy as its variance)."""
        if heading is None:
            return
        msg = heading_imu(heading.heading, heading.accuracy)
        msg.header.stamp = self._stamp(heading.stamp)
        msg.header.frame_id = self.heading_frame_id
        publisher.publish(msg)

    @staticmethod
    def _stamp(wall: float) -> Time:
        sec = math.floor(wall)
        return Time(sec=int(sec), nanosec=int((wall - sec) * 1e9))


def main(argv: list[str] | None = None) -> int:
    return run_driver(CanaeroTurretNode, argv)


if __name__ == "__main__":
    raise SystemExit(main())
