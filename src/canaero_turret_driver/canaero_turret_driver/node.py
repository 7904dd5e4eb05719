"""ROS 2 node for the CANaerospace turret: a thin layer over `TurretClient`.

The shared `GimbalDriverNode` owns the lifecycle, joint_states, joint_command, the jog
watchdog, ~/stop, ~/move_to, ~/home, presets, scans and /diagnostics plumbing. This
node adds the turret's specifics: the CAN parameters, the identifier-to-joint mapping,
preset 0 = the turret's remember/restore position (driver-side YAML presets beyond),
actuator mode, cover, fan, heaters and charging services, ~/device_command (IDS, TIS,
and the opt-in NIS/FPS), ~/fix, ~/heading and ~/global_yaw (sensor_msgs/Imu),
~/time_reference, ~/inclination, ~/zoom, and diagnostics from the status bytes, periphery
status, temperatures, voltages, EED events, message-code gaps, stale identifiers and the
transmission intervals in use (TIS at every connect for publish_rate). Relative MoveTo
goals go out as the turret's relative set-points; motion on an axis whose drive is off or
faulted is refused before anything is sent.

A turret node that stops sending (no frame for `node_timeout`) counts as a lost link:
the base node marks the device disconnected (ERROR in /diagnostics), stops publishing
joint_states and reconnects (IDS) every `reconnect_period` until frames resume.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Iterator, Sequence

from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus, TimeReference
from std_msgs.msg import Float64
from std_srvs.srv import SetBool

from gimbal_driver_common.device import DeviceInfo, JointSample
from gimbal_driver_common.diagnostics import Level
from gimbal_driver_common.joint_command import CommandError, validate_joint_command
from gimbal_driver_common.presets import PresetError
from gimbal_driver_common.ros.diagnostics import StatusPart
from gimbal_driver_common.ros.heading import heading_imu
from gimbal_driver_common.ros.legacy import DeviceError
from gimbal_driver_common.ros.legacy import HookedDriverNode as GimbalDriverNode
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_driver_common.ros.run import run_driver
from gimbal_msgs.msg import AxisState, Preset
from gimbal_msgs.srv import DeviceCommand, SetMode

from .client import AXES, ClientConfig, TurretClient, TurretError
from .protocol.datatypes import DataType
from .protocol.identifiers import (
    DATA_IDENTIFIERS,
    DEFAULT_ZOOM_POSITION_ID,
    ActuatorMode,
    AxisStatus,
    CoverState,
    TargetState,
    decode_periphery,
)

NODE_NAME = "canaero_turret_driver"
PRESET_DEVICE_INDEX = 0  # the turret's own remember/restore position
MODE_NAMES = {mode.name.lower(): mode for mode in ActuatorMode}
NODE_GROUPS = {
    "turret": "turret_node_id", "cover": "cover_node_id", "rover_gnss": "rover_gnss_node_id",
    "base_gnss": "base_gnss_node_id", "zoom": "zoom_node_id",
}
GROUP_OF_NODE_ID = {1: "turret", 2: "cover", 5: "rover_gnss", 6: "base_gnss", 7: "zoom"}
AXIS_KEYS = ("motor_temperature", "power_stage_temperature", "bus_voltage", "current",
             "humidity", "revolutions", "actuator_mode_state", "status")


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


POSITION_KEYS = frozenset(f"{axis}_position" for axis in AXES)
MIN_TIS_INTERVAL_MS = 1  # TIS counts whole milliseconds


class CanaeroTurretNode(GimbalDriverNode):
    DEFAULT_JOINT_NAMES = ("yaw", "pitch")
    DEFAULT_POSITION_MIN = (-math.pi, math.radians(-30.0))
    DEFAULT_POSITION_MAX = (math.pi, math.radians(60.0))
    DEFAULT_VELOCITY_MAX = (math.radians(60.0), math.radians(40.0))
    DEVICE_PRESETS = True  # preset 0 on the device, the rest in the YAML store
    STREAMED = True  # positions arrive as NOD broadcasts; publish each as it comes

    def __init__(self) -> None:
        super().__init__(NODE_NAME)
        if len(self.joint_names) != 2:
            raise ParameterError("parameter 'joint_names': the turret has exactly two joints "
                                 "(yaw, pitch)")
        self._axis_of = dict(zip(self.joint_names, AXES, strict=True))
        self._joint_of = {axis: joint for joint, axis in self._axis_of.items()}
        self._client: TurretClient | None = None
        self._client_lock = threading.Lock()
        self._remembered: dict[str, float] | None = None
        self._last_anomalies = 0
        self._last_published_fix: float | None = None
        self._last_published_utc: float | None = None
        self._last_published_heading: dict[str, float] = {}
        self._ids_info = None
        self._speed_warned = False
        self._eed_seen_count = 0
        self._eed_seen_at = -math.inf
        self._tis_refusal_logged = False
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
                              "s without any frame from the turret before it is silent "
                              "(link lost, ERROR)", value_range=(0.05, 600.0))
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
        self.transmission_intervals = _parse_intervals([i for i in p(
            "transmission_intervals", [""], "TIS at configure: <data key>=<ms> "
            "(e.g. yaw_position=20); 0 stops an identifier", element_type=str) if i])
        self.request_intervals = p(
            "request_intervals", True, "TIS at every (re)connect: yaw/pitch position and "
            "velocity every 1/publish_rate (the turret's own default is slower)")
        self.actuator_mode_name = p("actuator_mode", "", "actuator mode set at activate "
                                    "(free_run, without_brake, auto_brake; '' = leave)")
        if self.actuator_mode_name and self.actuator_mode_name not in MODE_NAMES:
            raise ParameterError(f"parameter 'actuator_mode': {self.actuator_mode_name!r} is "
                                 f"not one of {sorted(MODE_NAMES)}")
        self.monitored_nodes = [n for n in p(
            "monitored_nodes", ["turret", "cover", "rover_gnss", "base_gnss", "zoom"],
            "nodes whose data identifiers are watched for staleness", element_type=str) if n]
        unknown = set(self.monitored_nodes) - set(NODE_GROUPS)
        if unknown:
            raise ParameterError(f"parameter 'monitored_nodes': unknown {sorted(unknown)}; "
                                 f"known: {sorted(NODE_GROUPS)}")
        self.temperature_warn = p("temperature_warn", 70.0, "degC: WARN above",
                                  value_range=(-50.0, 200.0))
        self.temperature_error = p("temperature_error", 85.0, "degC: ERROR above",
                                   value_range=(-50.0, 200.0))
        self.eed_hold = p("eed_hold_time", 10.0, "s an EED event keeps the events status WARN",
                          value_range=(0.0, 3600.0))
        self.fix_frame_id = p("fix_frame_id", "gnss_base", "frame_id of ~/fix")
        self.inclination_frame_id = p("inclination_frame_id", "turret_base",
                                      "frame_id of ~/inclination")
        self.heading_frame_id = p("heading_frame_id", "gnss_rover",
                                  "frame_id of ~/heading and ~/global_yaw")
        self.allow_node_id_change = p("allow_node_id_change", False,
                                      "allow NIS (set_node_id) through ~/device_command")
        self.allow_data_download = p("allow_data_download", False,
                                     "allow DDS (download) through ~/device_command: it writes "
                                     "device memory")
        self.allow_flash_programming = p("allow_flash_programming", False,
                                         "allow FPS (store_configuration) through "
                                         "~/device_command")

    # ------------------------------------------------------------------ run-time parameters
    def declare_runtime_parameters(self) -> None:
        """Turret parameters that apply when set: TIS intervals, thresholds, frame ids.

        ``transmission_intervals`` are checked like at start-up, sent to the turret at
        once while connected (a node-service refusal refuses the set with its reply) and
        kept for the next connect. The CAN link, node-ids and opt-ins need a reconfigure.
        """

        def parse(items: Sequence[str]) -> dict[str, int]:
            return _parse_intervals([i for i in items if i])

        def send_intervals(items: Sequence[str]) -> None:
            client = self._client
            if client is None or not client.connected:
                return  # applied when the link opens (open_device)
            for key, interval in parse(items).items():
                client.set_transmission_interval(key, interval)

        def set_intervals(items: Sequence[str]) -> None:
            self.transmission_intervals = parse(items)

        self.runtime_parameter("transmission_intervals", set_intervals, send=send_intervals,
                               check=parse)
        self.runtime_parameter("eed_hold_time", "eed_hold")
        for name in ("temperature_warn", "temperature_error", "fix_frame_id",
                     "inclination_frame_id"):
            self.runtime_parameter(name, name)

    def _client_config(self) -> ClientConfig:
        return ClientConfig(
            interface=self.can_interface, channel=self.can_channel,
            bitrate=self.can_bitrate or None, bus_options=dict(self.can_options),
            client_node_id=self.client_node_id, zoom_position_id=self.zoom_position_id,
            service_channel=self.service_channel, service_timeout=self.service_timeout,
            service_attempts=self.service_attempts, stale_timeout=self.stale_timeout,
            node_timeout=self.node_timeout, reconnect_period=self.reconnect_period,
            pad_frames=self.pad_frames, yaw_sign=float(self.yaw_direction),
            pitch_sign=float(self.pitch_direction),
            allow_node_id_change=self.allow_node_id_change,
            allow_flash_programming=self.allow_flash_programming,
            transfer_first_number=self.transfer_first_number, **self.node_ids)

    # ------------------------------------------------------------------ interfaces
    def _create_device_interfaces(self) -> None:
        group = self.service_group
        self._fix_pub = self.create_publisher(NavSatFix, "~/fix", 10)
        self._heading_pub = self.create_publisher(Imu, "~/heading", 10)
        self._global_yaw_pub = self.create_publisher(Imu, "~/global_yaw", 10)
        self._time_pub = self.create_publisher(TimeReference, "~/time_reference", 10)
        self._inclination_pub = self.create_publisher(Vector3Stamped, "~/inclination", 10)
        self._zoom_pub = self.create_publisher(Float64, "~/zoom", 10)
        self.create_service(SetMode, "~/set_actuator_mode", self._on_set_mode,
                            callback_group=group)
        for name, method in (("set_cover", "set_cover"), ("set_fan", "set_fan"),
                             ("set_oes_heater", "set_oes_heater"),
                             ("set_drives_heater", "set_drives_heater"),
                             ("set_charging", "set_charging")):
            self.create_service(SetBool, f"~/{name}", self._bool_service(name, method),
                                callback_group=group)
        self.create_service(DeviceCommand, "~/device_command", self._on_device_command,
                            callback_group=group)
        self.add_periodic(0.1, self._publish_sensors)

    def link_description(self) -> str:
        return f"{self.can_interface}:{self.can_channel}"

    @contextlib.contextmanager
    def _device(self) -> Iterator[TurretClient]:
        """The open client; client errors become DeviceError with their message."""
        client = self._client
        if client is None:
            raise DeviceError("CAN interface not open")
        try:
            yield client
        except TurretError as exc:
            raise DeviceError(str(exc)) from exc

    # ------------------------------------------------------------------ device hooks
    def _on_sample(self, sample) -> None:
        """Publish joint_states as soon as both axes of a broadcast cycle are in.

        Runs on the client's receive thread. Yaw and pitch positions are separate frames;
        waking the device thread on the first would publish it and then hold the second
        for a publish period. If one axis goes quiet, the base node's periodic check still
        publishes the other.
        """
        if sample.key not in POSITION_KEYS:
            return
        self._cycle_keys.add(sample.key)
        if self._cycle_keys >= POSITION_KEYS:
            self._cycle_keys.clear()
            self.notify_new_data()

    def open_device(self) -> DeviceInfo:
        config = self._client_config()
        client = TurretClient(config)
        self._cycle_keys: set[str] = set()
        client.on_sample = self._on_sample
        try:
            client.open()
            info = client.identify()
            refused = client.request_intervals(self._interval_requests())
        except TurretError:
            client.close()
            raise
        if refused and not self._tis_refusal_logged:
            self._tis_refusal_logged = True
            self.get_logger().warning(
                f"the turret refused TIS for {', '.join(sorted(refused))}: rate and staleness "
                "checks follow the intervals it actually sends (see /diagnostics "
                "'transmission intervals')")
        self._client = client
        self._ids_info = info
        node = config.turret_node_id
        return DeviceInfo(
            model="CANaerospace turret",
            serial_number=f"node {node}",
            firmware_version=f"hw {info.hardware_revision} sw {info.software_revision}",
            hardware_id=f"canaerospace node {node} on {self.link_description()}",
        )

    def _interval_requests(self) -> dict[str, int]:
        """TIS requests for a (re)connect: what joint_states needs, then the parameter.

        The ICD does not say how often a turret sends by default (a real one: 100 ms), so
        with `request_intervals` the positions and velocities are asked for at
        1/publish_rate; `transmission_intervals` entries override or add to that.
        """
        intervals: dict[str, int] = {}
        if self.request_intervals:
            interval_ms = max(MIN_TIS_INTERVAL_MS, round(1000.0 / self.publish_rate))
            intervals = {f"{axis}_{what}": interval_ms for axis in AXES
                         for what in ("position", "velocity")}
        intervals.update(self.transmission_intervals)
        return intervals

    def expected_joint_rate(self) -> float:
        """publish_rate, or the slower rate at which the turret sends both positions.

        Taken from the interval the turret accepted by TIS or, when it refused, the one
        observed on the bus; until that is known, publish_rate.
        """
        client = self._client
        if client is None:
            return self.publish_rate
        intervals = [client.interval_of(key) for key in sorted(POSITION_KEYS)]
        if any(interval is None or interval <= 0 for interval in intervals):
            return self.publish_rate
        return min(self.publish_rate, 1.0 / max(intervals))  # type: ignore[type-var]

    def on_activate(self, state):
        result = super().on_activate(state)
        if self.actuator_mode_name and self._client is not None:
            mode = MODE_NAMES[self.actuator_mode_name]
            try:
                for axis in AXES:
                    self._client.set_actuator_mode(axis, mode)
            except TurretError as exc:
                self.get_logger().error(f"setting actuator mode at activate failed: {exc}")
        return result

    def close_device(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            client.close()

    def link_healthy(self) -> bool:
        client = self._client
        if client is None or not client.connected:
            return False
        if client.node_silent():
            seen = client.node_last_seen(client.config.turret_node_id)
            silent_for = "" if seen is None else f" for {time.monotonic() - seen:.1f} s"
            raise DeviceError(f"turret node {client.config.turret_node_id} silent{silent_for} "
                              f"(no CAN frames on {self.link_description()})")
        return True

    def poll_device(self) -> JointSample | None:
        client = self._client
        if client is None:
            raise DeviceError("CAN interface not open")
        positions, velocities, efforts, moving = {}, {}, {}, {}
        stamp = 0.0
        for axis in AXES:
            joint = self._joint_of[axis]
            position = client.latest(f"{axis}_position")
            if position is None or client.is_stale(f"{axis}_position"):
                return None  # never publish stale positions as current
            positions[joint] = position.si
            stamp = max(stamp, position.stamp)
            velocity = client.latest(f"{axis}_velocity")
            velocities[joint] = velocity.si if velocity is not None else math.nan
            current = client.latest(f"{axis}_current")
            if current is not None:
                efforts[joint] = current.si
            status = client.latest(f"{axis}_status")
            target = AxisStatus.decode(status.value).target if status is not None else None
            moving[joint] = target in (TargetState.NOT_REACHED, TargetState.JOG) or \
                abs(velocities[joint] or 0.0) > 1e-4
        if len(efforts) != len(positions):
            efforts = {}
        return JointSample(positions, velocities, efforts, stamp, moving)

    def send_moves(self, moves: dict[str, tuple[float, float | None]]) -> None:
        with self._device() as client:
            self._warn_speed_once(moves)
            for joint, (position, _speed) in moves.items():
                client.move_to(self._axis_of[joint], position)

    def send_relative_moves(self, offsets: dict[str, float],
                            moves: dict[str, tuple[float, float | None]]) -> bool:
        """A relative MoveTo as the turret's relative set-points (6.1.4, 1302/1312).

        The base node has already checked the resolved targets against the limits; the
        device gets the offsets themselves, so it moves by exactly that much from where
        it is (no round trip through a possibly older position sample).
        """
        with self._device() as client:
            self._warn_speed_once(moves)
            for joint, offset in offsets.items():
                client.move_by(self._axis_of[joint], offset)
        return True

    def _warn_speed_once(self, moves: dict[str, tuple[float, float | None]]) -> None:
        if self._speed_warned or all(speed is None for _, speed in moves.values()):
            return
        self._speed_warned = True
        self.get_logger().warning(
            "the turret's set-points have no speed field: moves use the device's own "
            "profile (speed checked against velocity_max only)")

    def axis_refusal(self, joints: Sequence[str]) -> str | None:
        """Refuse motion on an axis whose status byte says its drive is off or faulted."""
        client = self._client
        if client is None:
            return None
        reasons = []
        for joint in joints:
            axis = self._axis_of.get(joint)
            sample = client.latest(f"{axis}_status") if axis is not None else None
            if sample is None or client.is_stale(f"{axis}_status"):
                continue
            status = AxisStatus.decode(sample.value)
            if status.enabled:
                continue
            why = ("drive in free run (not driven)" if status.actuator_mode ==
                   ActuatorMode.FREE_RUN else "drive disabled (fault)")
            reasons.append(f"joint {joint!r}: {why}, status byte 0x{status.raw:02X}")
        if not reasons:
            return None
        return ("; ".join(reasons) + "; ~/reset_faults or ~/set_actuator_mode enables it "
                "again")

    def send_jogs(self, jogs: dict[str, float]) -> None:
        with self._device() as client:
            for joint, velocity in jogs.items():
                if velocity == 0.0:
                    client.stop([self._axis_of[joint]])
                else:
                    client.jog(self._axis_of[joint], velocity)

    def stop_axes(self, joints: Sequence[str] | None) -> None:
        with self._device() as client:
            axes = AXES if joints is None else [self._axis_of[j] for j in joints]
            client.stop(list(axes))

    def reset_faults(self) -> str:
        """The ICD has no fault reset; re-sending the actuator mode re-initialises a drive."""
        with self._device() as client:
            sent = []
            for axis in AXES:
                sample = client.latest(f"{axis}_actuator_mode_state")
                mode = ActuatorMode.AUTO_BRAKE
                if sample is not None and sample.value in tuple(ActuatorMode):
                    mode = ActuatorMode(sample.value)
                if self.actuator_mode_name:
                    mode = MODE_NAMES[self.actuator_mode_name]
                client.set_actuator_mode(axis, mode)
                sent.append(f"{self._joint_of[axis]}={mode.name.lower()}")
            client.events.clear()
        return "actuator mode re-sent to re-initialise the drives (" + ", ".join(sent) + ")"

    # ------------------------------------------------------------------ presets
    def device_set_preset(self, index: int, name: str,
                          positions: dict[str, float] | None) -> str:
        if index == PRESET_DEVICE_INDEX:
            if positions is not None:
                raise DeviceError("preset 0 is the turret's remembered position: it can only "
                                  "store the current position (use_current_position=true)")
            with self._device() as client:
                client.remember_position()
            self._remembered = self.current_positions()
            return "preset 0: the turret remembered its current position"
        if positions is None:
            positions = self.current_positions()
            if not positions:
                raise DeviceError("no joint position received yet")
        assert self.preset_store is not None
        self.preset_store.set(index, name, positions)
        return f"preset {index} stored (driver-side): " + ", ".join(
            f"{k}={v:.4f}" for k, v in positions.items())

    def device_goto_preset(self, index: int, speed: float) -> str:
        if index == PRESET_DEVICE_INDEX:
            if speed > 0:
                raise DeviceError("preset 0 (turret set-to-saved-position) has no speed; "
                                  "use speed 0")
            with self._device() as client:
                client.restore_position()
            if self._remembered:
                self.commanded_targets.update(self._remembered)
            return "moving to preset 0 (the turret's saved position)"
        assert self.preset_store is not None
        try:
            preset = self.preset_store.get(index)
        except PresetError as exc:
            raise DeviceError(str(exc)) from exc
        names = [n for n in preset.positions if n in self.limits]
        speeds = [speed] * len(names) if speed > 0 else []
        plan = validate_joint_command(names, [preset.positions[n] for n in names], speeds,
                                      self.limits)
        self.jog_watchdog.cancel(names)
        self.send_moves(plan.moves)
        self.commanded_targets.update({k: v[0] for k, v in plan.moves.items()})
        return f"moving to preset {index} ({preset.name})"

    def device_list_presets(self) -> list[Preset]:
        presets = []
        if self._remembered is not None:
            presets.append(Preset(index=0, name="turret saved position",
                                  joint_names=list(self._remembered),
                                  positions=list(self._remembered.values())))
        assert self.preset_store is not None
        presets += [Preset(index=p.index, name=p.name, joint_names=list(p.positions),
                           positions=list(p.positions.values()))
                    for p in self.preset_store.list()]
        return presets

    def device_clear_preset(self, index: int | None) -> str:
        assert self.preset_store is not None
        if index == PRESET_DEVICE_INDEX:
            self._remembered = None
            return ("preset 0 lives in the turret and cannot be erased; the driver forgot "
                    "its record of it")
        try:
            self.preset_store.clear(index)
        except PresetError as exc:
            raise DeviceError(str(exc)) from exc
        if index is None:
            self._remembered = None
            return "all driver-side presets cleared (the turret keeps its saved position)"
        return f"preset {index} cleared"

    # ------------------------------------------------------------------ services
    def _on_set_mode(self, request, response):
        def action() -> str:
            text = request.mode.strip().lower()
            targets: list[tuple[str, str]] = []
            for part in text.replace(",", " ").split():
                joint, sep, mode = part.partition("=")
                if not sep:
                    targets += [(j, joint) for j in self.joint_names]
                elif joint not in self._axis_of:
                    raise CommandError(f"unknown joint {joint!r}; joints: {self.joint_names}")
                else:
                    targets.append((joint, mode))
            if not targets:
                raise CommandError(f"give a mode: one of {sorted(MODE_NAMES)} (or joint=mode)")
            for _, mode in targets:
                if mode not in MODE_NAMES:
                    raise CommandError(f"unknown actuator mode {mode!r}; modes: "
                                       f"{sorted(MODE_NAMES)}")
            with self._device() as client:
                for joint, mode in targets:
                    client.set_actuator_mode(self._axis_of[joint], MODE_NAMES[mode])
            return "actuator mode " + ", ".join(f"{j}={m}" for j, m in targets)

        return self.serve_request(response, action)

    def _bool_service(self, name: str, method: str):
        def callback(request, response):
            def action() -> str:
                with self._device() as client:
                    getattr(client, method)(bool(request.data))
                what = name.removeprefix("set_").replace("_", " ")
                if name == "set_cover":
                    return "cover " + ("opening" if request.data else "closing")
                return f"{what} " + ("on" if request.data else "off")

            return self.serve_request(response, action)

        return callback

    def _on_device_command(self, request, response):
        """identify [node-id] | set_interval <key> <ms> | upload <memid> <length> |
        download <memid> <hex> | set_node_id <new> [node-id] |
        store_configuration <security code> [node-id]"""
        results: list[str] = []

        def number(text: str) -> int:
            try:
                return int(text, 0)
            except ValueError as exc:
                raise CommandError(f"{text!r} is not an integer") from exc

        def action() -> str:
            args = list(request.arguments)
            command = request.command.strip()
            with self._device() as client:
                if command == "identify":
                    node = number(args[0]) if args else None
                    info = client.identify(node)
                    results.extend([f"hardware_revision={info.hardware_revision}",
                                    f"software_revision={info.software_revision}",
                                    f"identifier_distribution={info.identifier_distribution}",
                                    f"header_type={info.header_type}"])
                    return "IDS answered"
                if command == "set_interval":
                    if len(args) != 2:
                        raise CommandError("set_interval needs <data key> <ms>")
                    client.set_transmission_interval(args[0], number(args[1]))
                    return f"{args[0]} every {number(args[1])} ms"
                if command == "set_node_id":
                    if not args:
                        raise CommandError("set_node_id needs <new node-id> [node-id]")
                    node = number(args[1]) if len(args) > 1 else client.config.turret_node_id
                    new_id = number(args[0])
                    client.set_node_id(new_id, node)
                    for name, value in self.node_ids.items():
                        if value == node:
                            self.node_ids[name] = new_id  # reconnects use the new id
                    self.get_logger().warning(
                        f"node {node} now has node-id {new_id}; put it in the parameter file, "
                        "and store it with store_configuration (FPS) to keep it after a "
                        "power cycle")
                    return f"node-id {node} changed to {new_id}"
                if command == "upload":
                    if len(args) != 2:
                        raise CommandError("upload needs <memory id> <length in bytes>")
                    data = client.upload(number(args[0]), number(args[1]))
                    results.append(data.hex())
                    return f"{len(data)} bytes read from memory {number(args[0])} (DUS)"
                if command == "download":
                    if not self.allow_data_download:
                        raise CommandError("data download (DDS) writes device memory and is "
                                           "disabled; set allow_data_download to use it")
                    if len(args) != 2:
                        raise CommandError("download needs <memory id> <hex bytes>")
                    try:
                        data = bytes.fromhex(args[1])
                    except ValueError as exc:
                        raise CommandError(f"{args[1]!r} is not hex bytes") from exc
                    checksum = client.download(number(args[0]), data)
                    results.append(f"checksum={checksum}")
                    return f"{len(data)} bytes written to memory {number(args[0])} (DDS)"
                if command == "store_configuration":
                    if not args:
                        raise CommandError("store_configuration needs <security code>")
                    node = number(args[1]) if len(args) > 1 else None
                    client.store_configuration(number(args[0]), node)
                    return "configuration stored in flash"
            raise CommandError(f"unknown command {command!r}; commands: identify, "
                               "set_interval, upload, download, set_node_id, "
                               "store_configuration")

        response = self.serve_request(response, action)
        response.results = results
        return response

    # ------------------------------------------------------------------ topics
    def _publish_sensors(self) -> None:
        client = self._client
        if client is None or not self.active:
            return
        latitude = client.latest("latitude")
        longitude = client.latest("longitude")
        if latitude is not None and longitude is not None and \
                latitude.received != self._last_published_fix:
            self._last_published_fix = latitude.received
            fix = NavSatFix()
            fix.header.stamp = self._stamp(latitude.stamp)
            fix.header.frame_id = self.fix_frame_id
            fresh = not (client.is_stale("latitude") or client.is_stale("longitude"))
            fix.status.status = NavSatStatus.STATUS_FIX if fresh else NavSatStatus.STATUS_NO_FIX
            fix.status.service = NavSatStatus.SERVICE_GPS
            fix.latitude, fix.longitude = latitude.si, longitude.si
            altitude = client.latest("altitude_msl")
            fix.altitude = altitude.si if altitude is not None else math.nan
            accuracy = client.latest("position_accuracy")
            if accuracy is not None:
                variance = accuracy.si ** 2
                fix.position_covariance = [variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0,
                                           variance]
                fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_APPROXIMATED
            else:
                fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
            self._fix_pub.publish(fix)
        self._publish_heading(client, "rover_heading", self._heading_pub)
        self._publish_heading(client, "global_yaw", self._global_yaw_pub)
        utc = client.latest("utc_time")
        if utc is not None and utc.received != self._last_published_utc \
                and not client.is_stale("utc_time"):
            self._last_published_utc = utc.received
            reference = TimeReference()
            reference.header.stamp = self._stamp(utc.stamp)
            reference.time_ref = self._stamp(float(utc.value))
            reference.source = "base_gnss"
            self._time_pub.publish(reference)
        pitch, roll = client.latest("global_pitch"), client.latest("global_roll")
        if pitch is not None and roll is not None and not client.is_stale("global_pitch"):
            msg = Vector3Stamped()
            msg.header.stamp = self._stamp(pitch.stamp)
            msg.header.frame_id = self.inclination_frame_id
            msg.vector.x, msg.vector.y = roll.si, pitch.si
            self._inclination_pub.publish(msg)
        zoom = client.latest("zoom_position")
        if zoom is not None and not client.is_stale("zoom_position") and zoom.si is not None:
            self._zoom_pub.publish(Float64(data=zoom.si))

    def _publish_heading(self, client: TurretClient, key: str, publisher) -> None:
        """One fresh heading frame -> one Imu; the accuracy is the rover GNSS's (7.3.2)."""
        sample = client.latest(key)
        if sample is None or sample.si is None or client.is_stale(key) \
                or self._last_published_heading.get(key) == sample.received:
            return
        self._last_published_heading[key] = sample.received
        accuracy = client.latest("rover_heading_accuracy")
        fresh_accuracy = accuracy is not None and accuracy.si is not None \
            and not client.is_stale("rover_heading_accuracy")
        msg = heading_imu(sample.si, abs(accuracy.si) if fresh_accuracy else None)
        msg.header.stamp = self._stamp(sample.stamp)
        msg.header.frame_id = self.heading_frame_id
        publisher.publish(msg)

    @staticmethod
    def _stamp(wall: float):
        from builtin_interfaces.msg import Time

        sec = math.floor(wall)
        return Time(sec=int(sec), nanosec=int((wall - sec) * 1e9))

    # ------------------------------------------------------------------ diagnostics
    def _monitored_keys(self, client: TurretClient) -> list[str]:
        keys = []
        for ident in client.data_identifiers():
            if not ident.used:
                continue
            if GROUP_OF_NODE_ID.get(ident.node_id or 0) in self.monitored_nodes:
                keys.append(ident.key)
        return keys

    def device_status_parts(self) -> list[StatusPart]:
        client = self._client
        if client is None:
            return []
        now = time.monotonic()
        parts = [self._node_part(client, now)]
        parts += [self._axis_part(client, axis, now) for axis in AXES]
        parts.append(self._periphery_part(client))
        parts.append(self._sequence_part(client))
        parts.append(self._events_part(client))
        parts.append(self._stale_part(client, now))
        parts.append(self._interval_part(client))
        return parts

    def _interval_part(self, client: TurretClient) -> StatusPart:
        """Which transmission intervals the rate and staleness checks are based on.

        A turret that refuses TIS is not a fault (the ICD leaves intervals to the device):
        the part stays OK and says once, in its message, that the observed rates are used.
        """
        values = []
        for key in sorted(self._interval_requests()):
            accepted = client.accepted_interval_ms(key)
            observed = client.interval_of(key)
            if accepted is not None:
                values.append((key, f"{accepted} ms (accepted)"))
            elif observed is not None:
                values.append((key, f"{observed * 1000:.0f} ms (observed)"))
            else:
                values.append((key, "not received yet"))
        values.append(("expected_joint_states_hz", f"{self.expected_joint_rate():.2f}"))
        refused = client.refused_intervals
        if refused:
            for key, reason in sorted(refused.items()):
                values.append((f"refused_{key}", reason))
            return StatusPart("transmission intervals", Level.OK,
                              f"the turret refused TIS for {', '.join(sorted(refused))}: "
                              "checks follow the intervals it sends", values)
        return StatusPart("transmission intervals", Level.OK,
                          "intervals accepted by the turret", values)

    def _node_part(self, client: TurretClient, now: float) -> StatusPart:
        counters = client.counters
        values = [("interface", self.link_description()),
                  ("turret_node_id", str(client.config.turret_node_id)),
                  ("frames", str(counters.frames)), ("malformed", str(counters.malformed)),
                  ("unknown_ids", str(counters.unknown)),
                  ("type_mismatch", str(counters.type_mismatch)),
                  ("foreign_node", str(counters.foreign_node)),
                  ("bus_errors", str(counters.bus_errors)),
                  ("interface_reopened", str(counters.reconnects))]
        if counters.last_malformed:
            values.append(("last_malformed", counters.last_malformed))
        for group, param in NODE_GROUPS.items():
            node_id = getattr(client.config, param)
            seen = client.node_last_seen(node_id)
            values.append((f"{group}_last_frame_age_s",
                           "never" if seen is None else f"{now - seen:.2f}"))
        if client.node_silent():
            return StatusPart("turret node", Level.ERROR, "turret node silent", values)
        return StatusPart("turret node", Level.OK, "turret node talking", values)

    def _axis_part(self, client: TurretClient, axis: str, now: float) -> StatusPart:
        joint = self._joint_of[axis]
        values: list[tuple[str, str]] = []
        level, problems = Level.OK, []
        for key in AXIS_KEYS:
            sample = client.latest(f"{axis}_{key}")
            if sample is None:
                continue
            if key == "status":
                status = AxisStatus.decode(sample.value)
                values += [("status_byte", f"0x{status.raw:02X}"),
                           ("target", status.target_name), ("actuator_mode", status.mode_name),
                           ("enabled", str(status.enabled))]
                if not status.enabled and status.actuator_mode != ActuatorMode.FREE_RUN:
                    level = max(level, Level.ERROR)
                    problems.append("drive disabled (fault)")
                elif not status.enabled:
                    level = max(level, Level.WARN)
                    problems.append("free run: not driven")
            elif key == "humidity":
                values.append(("humidity_percent", f"{sample.value:.1f}"))
            elif key == "actuator_mode_state":
                continue
            else:
                text = f"{sample.si:.2f}" if isinstance(sample.si, float) else str(sample.value)
                values.append((key, text))
                if key.endswith("temperature") and isinstance(sample.si, float):
                    if sample.si > self.temperature_error:
                        level = max(level, Level.ERROR)
                        problems.append(f"{key} {sample.si:.1f} degC")
                    elif sample.si > self.temperature_warn:
                        level = max(level, Level.WARN)
                        problems.append(f"{key} {sample.si:.1f} degC")
        message = "; ".join(problems) if problems else "OK"
        return StatusPart(joint, Level(level), message, values)

    def _periphery_part(self, client: TurretClient) -> StatusPart:
        values: list[tuple[str, str]] = []
        level, problems = Level.OK, []
        sample = client.latest("periphery_status")
        if sample is not None:
            values.append(("periphery_status", f"0x{sample.value:08X}"))
            for key, is_set in decode_periphery(int(sample.value)).items():
                values.append((key, str(is_set)))
                if key == "case_temperature_sensor_fault" and is_set:
                    level = Level.WARN
                    problems.append("case temperature sensor fault")
        cover = client.latest("cover_state")
        if cover is not None:
            try:
                values.append(("cover", CoverState(cover.value).name.lower()))
            except ValueError:
                values.append(("cover", f"undefined({cover.value})"))
        for key in ("case_temperature", "charging_current", "charging_state", "fan_state",
                    "oes_heater_state"):
            value = client.latest(key)
            if value is not None:
                values.append((key, f"{value.si:.2f}" if client.data_type_of(key)
                               == DataType.FLOAT else str(value.value)))
        case = client.latest("case_temperature")
        if case is not None and case.si > self.temperature_warn:
            level = Level.WARN
            problems.append(f"case temperature {case.si:.1f} degC")
        return StatusPart("periphery", level, "; ".join(problems) or "OK", values)

    def _sequence_part(self, client: TurretClient) -> StatusPart:
        stats = client.sequences.all_stats()
        lost = sum(s.lost for s in stats.values())
        repeated = sum(s.repeated for s in stats.values())
        late = sum(s.late for s in stats.values())
        total = lost + repeated + late
        new = total - self._last_anomalies
        self._last_anomalies = total
        values = [("lost", str(lost)), ("repeated", str(repeated)), ("late", str(late)),
                  ("restarts", str(sum(s.restarts for s in stats.values())))]
        unsequenced = sorted(can_id for (_, can_id), s in stats.items() if s.unsequenced)
        if unsequenced:
            values.append(("unsequenced_ids", " ".join(map(str, unsequenced))))
        for (_node_id, can_id), s in sorted(stats.items()):
            if s.anomalies:
                values.append((f"id_{can_id}", f"lost {s.lost} repeated {s.repeated} "
                                              f"late {s.late}"))
        if new > 0:
            return StatusPart("message codes", Level.WARN,
                              f"{new} message-code gap(s)/repeat(s) since the last report",
                              values)
        return StatusPart("message codes", Level.OK, "in sequence", values)

    def _events_part(self, client: TurretClient) -> StatusPart:
        events = list(client.events)
        values = [("count", str(client.counters.eed))]
        if not events:
            return StatusPart("emergency events", Level.OK, "none", values)
        latest = events[-1]
        values += [("last_node", str(latest.node_id)),
                   ("last_error_code", f"0x{latest.error_code:04X}"),
                   ("last_operation", str(latest.operation_id)),
                   ("last_location", str(latest.location_id))]
        recent = self._event_recent(client)
        if recent:
            return StatusPart("emergency events", Level.WARN, latest.describe(), values)
        return StatusPart("emergency events", Level.OK, "no recent event", values)

    def _event_recent(self, client: TurretClient) -> bool:
        count = client.counters.eed
        now = time.monotonic()
        if count != self._eed_seen_count:
            self._eed_seen_count = count
            self._eed_seen_at = now
        return now - self._eed_seen_at <= self.eed_hold

    def _stale_part(self, client: TurretClient, now: float) -> StatusPart:
        stale = [key for key in self._monitored_keys(client) if client.is_stale(key, now)]
        values = [("stale", ", ".join(stale))] if stale else []
        if stale:
            return StatusPart("data freshness", Level.WARN,
                              f"{len(stale)} identifier(s) stale: {', '.join(stale[:6])}"
                              + (" ..." if len(stale) > 6 else ""), values)
        return StatusPart("data freshness", Level.OK, "all monitored identifiers fresh", values)

    # ------------------------------------------------------------------ ~/status
    def device_mode(self) -> str:
        client = self._client
        if client is None:
            return ""
        modes = []
        for axis in AXES:
            sample = client.latest(f"{axis}_actuator_mode_state")
            if sample is not None:
                try:
                    name = ActuatorMode(sample.value).name.lower()
                except ValueError:
                    name = f"undefined({sample.value})"
                modes.append(f"{self._joint_of[axis]}={name}")
        return " ".join(modes)

    def axis_details(self, joint: str) -> dict[str, object]:
        client = self._client
        if client is None:
            return {}
        sample = client.latest(f"{self._axis_of[joint]}_status")
        if sample is None:
            return {}
        status = AxisStatus.decode(sample.value)
        details: dict[str, object] = {"calibrated": True}
        if not status.enabled:
            fault = status.actuator_mode != ActuatorMode.FREE_RUN
            details["state"] = AxisState.STATE_FAULT if fault else AxisState.STATE_DISABLED
            details["active_errors"] = ["drive_disabled"] if fault else ["free_run"]
        return details

    def device_errors(self) -> list[str]:
        client = self._client
        if client is None:
            return []
        errors = []
        for axis in AXES:
            sample = client.latest(f"{axis}_status")
            if sample is not None:
                status = AxisStatus.decode(sample.value)
                if not status.enabled and status.actuator_mode != ActuatorMode.FREE_RUN:
                    errors.append(f"{self._joint_of[axis]}_drive_disabled")
        periphery = client.latest("periphery_status")
        if periphery is not None and decode_periphery(int(periphery.value))[
                "case_temperature_sensor_fault"]:
            errors.append("case_temperature_sensor_fault")
        if self._event_recent(client) and client.events:
            errors.append(client.events[-1].describe())
        return errors


def main(argv: list[str] | None = None) -> int:
    return run_driver(CanaeroTurretNode, argv)


if __name__ == "__main__":
    raise SystemExit(main())
