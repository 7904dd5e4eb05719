"""The turret as a gimbal_driver_common `Device`: `TurretClient` in joints, SI and REP-103.

No ROS here. The controller of gimbal_driver_common supervises the link (open, IDS,
reconnect every `reconnect_period`, link state); this adapter maps the turret's axes to
the configured joints, applies each axis' installation direction (`yaw_direction`,
`pitch_direction`: +1 or -1 between the device's count and REP-103), reads joint samples
from the client's broadcast cache and offers the turret's extras (actuator modes,
periphery switches, node services, GNSS/heading/inclination/zoom readings) as plain
methods the node calls through `controller.call`.

Capabilities: preset slot 0 is the turret's own remember/restore position
(`TurretPresets.handles(0)`; the core's Motion keeps every other slot in the YAML store)
and `TurretStatus` (status.py) decodes the status identifiers for /diagnostics and
~/status. The turret has no homing routine and no scans of its own.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from gimbal_driver_common.config import Logger
from gimbal_driver_common.device import (
    Device,
    DeviceInfo,
    DevicePresets,
    Geolocation,
    JointSample,
    Moves,
    PostedWrite,
)
from gimbal_driver_common.errors import DeviceRefused, InvalidRequest, LinkError
from gimbal_driver_common.geodesy import (
    Attitude,
    DevicePose,
    GeoPoint,
    OrientationFix,
    PositionFix,
)

from .client import AXES, CommandError, Sample, TurretClient
from .protocol.identifiers import ActuatorMode, AxisStatus, TargetState
from .status import TurretStatus

MODE_NAMES = {mode.name.lower(): mode for mode in ActuatorMode}
ICD_POSITION_LIMIT_DEG = 180.0  # set-point range "-180 ÷ 180" (6.1.2, 6.1.1 pitch)
#: how long activation waits for both axes to report their actuator mode (the simulator's
#: status byte comes every 100 ms, its mode state every 500 ms)
MODE_REPORT_WAIT_S = 1.0
POSITION_KEYS = frozenset(f"{axis}_position" for axis in AXES)
MIN_TIS_INTERVAL_MS = 1  # TIS counts whole milliseconds
PRESET_DEVICE_INDEX = 0  # the turret's own remember/restore position
#: the on/off services of the node -> the client method that sends them
SWITCHES = {"set_cover": "set_cover", "set_fan": "set_fan", "set_oes_heater": "set_oes_heater",
            "set_drives_heater": "set_drives_heater", "set_charging": "set_charging"}
#: node-id parameter name -> the ClientConfig field it sets
NODE_ID_FIELDS = ("turret_node_id", "cover_node_id", "rover_gnss_node_id",
                  "base_gnss_node_id", "zoom_node_id")
DEVICE_COMMANDS = ("identify", "set_interval", "upload", "download", "set_node_id",
                   "store_configuration")


@dataclass
class TurretSettings:
    """What the adapter needs beyond the CAN link; the node keeps one and updates the
    run-time fields in place (the adapter reads them when it needs them)."""

    joint_names: Sequence[str] = ("yaw", "pitch")
    yaw_direction: int = 1
    pitch_direction: int = 1
    #: TIS at every connect: positions and velocities at 1/publish_rate
    request_intervals: bool = True
    #: TIS at every connect on top of (or instead of) the above: data key -> ms (run time)
    transmission_intervals: dict[str, int] = field(default_factory=dict)
    #: actuator mode sent at activate and by reset_faults ('' = leave the turret's own)
    actuator_mode: str = ""
    allow_data_download: bool = False
    # thresholds and watch list of the diagnostics (status.py); run time
    temperature_warn: float = 70.0
    temperature_error: float = 85.0
    eed_hold: float = 10.0
    monitored_nodes: Sequence[str] = ("turret", "cover", "rover_gnss", "base_gnss", "zoom")
    #: m, the geoid height N at the site (ellipsoid height = the base GNSS's mean-sea-level
    #: altitude + N); None: unknown, so ~/look_at_geo has no ellipsoid altitude (run time)
    geoid_height: float | None = None


@dataclass(frozen=True)
class GnssFix:
    """One base-GNSS position (7.2): degrees, metres; `fresh` False once it went stale."""

    stamp: float
    latitude: float
    longitude: float
    altitude: float
    accuracy: float | None  # m (1 sigma), None when the node sent none
    fresh: bool


@dataclass(frozen=True)
class Heading:
    """A compass heading (rad, clockwise from north) and its accuracy (rad) if known."""

    stamp: float
    heading: float
    accuracy: float | None


@dataclass(frozen=True)
class Inclination:
    """The turret base's roll and pitch (rad)."""

    stamp: float
    roll: float
    pitch: float


class TurretPresets(DevicePresets):
    """Slot 0 is the turret's remember/restore position; the driver remembers where it was."""

    def __init__(self, device: TurretDevice) -> None:
        self.device = device
        self.remembered: dict[str, float] | None = None

    def handles(self, index: int) -> bool:
        return index == PRESET_DEVICE_INDEX

    def set(self, index: int, name: str, positions: dict[str, float] | None) -> str:
        if positions is not None:
            raise InvalidRequest("preset 0 is the turret's remembered position: it can only "
                                 "store the current position (use_current_position=true)")
        self.device.client.remember_position()
        self.remembered = self.device.positions()
        return "preset 0: the turret remembered its current position"

    def goto(self, index: int, speed: float) -> str:
        if speed > 0:
            raise InvalidRequest("preset 0 (turret set-to-saved-position) has no speed; "
                                 "use speed 0")
        self.device.client.restore_position()
        return "moving to preset 0 (the turret's saved position)"

    def target(self, index: int) -> dict[str, float] | None:
        return dict(self.remembered) if self.remembered else None

    def list(self) -> list[tuple[int, str, dict[str, float]]]:
        if self.remembered is None:
            return []
        return [(PRESET_DEVICE_INDEX, "turret saved position", dict(self.remembered))]

    def clear(self, index: int | None) -> str:
        self.remembered = None
        if index is None:
            return "all driver-side presets cleared (the turret keeps its saved position)"
        return ("preset 0 lives in the turret and cannot be erased; the driver forgot its "
                "record of it")


class TurretGeolocation(Geolocation):
    """Where the turret stands and faces: the base GNSS position (7.4: latitude, longitude,
    altitude above mean sea level plus ``geoid_height``, accuracy estimate), the rover
    GNSS heading (7.3.1, accuracy 7.3.2) and the base's inclinometer (7.1.31-32).

    The ICD gives the inclinometer no sign convention; it is read as the aerospace one
    (pitch nose-up positive, roll right side down positive), i.e. REP-103 roll = global
    roll, REP-103 pitch = -global pitch (README, decision 21).
    """

    POSITION_KEYS = ("latitude", "longitude", "altitude_msl")
    ORIENTATION_KEYS = ("rover_heading", "global_roll", "global_pitch")

    def __init__(self, device: TurretDevice) -> None:
        self.device = device

    def _readings(self, keys: Sequence[str], what: str) -> tuple[list[Sample], str | None]:
        """The samples of ``keys``, or why they cannot be used (never received, stale)."""
        client = self.device.client
        samples = [client.latest(key) for key in keys]
        absent = [k for k, s in zip(keys, samples, strict=True) if s is None or s.si is None]
        if absent:
            return [], f"no {what} received ({', '.join(absent)})"
        stale = [k for k in keys if client.is_stale(k)]
        if stale:
            age = max(client.age(k) or 0.0 for k in stale)
            return [], (f"{what} stale: no {', '.join(stale)} for {age:.1f} s "
                        f"(stale after {client.stale_timeout_for(stale[0]):g} s)")
        return samples, None

    def pose(self) -> DevicePose:
        missing: dict[str, str] = {}
        position = orientation = None
        samples, why = self._readings(self.POSITION_KEYS, "base GNSS position")
        geoid_height = self.device.settings.geoid_height
        if why is None and geoid_height is None:
            why = ("the base GNSS gives the altitude above mean sea level (ICD 7.4.3): set "
                   "geoid_height (the geoid height N at the site, m) to make it a height above "
                   "the WGS84 ellipsoid")
        if why is not None:
            missing["position"] = why
        else:
            latitude, longitude, altitude = samples
            accuracy = self.device._fresh("position_accuracy")
            position = PositionFix(
                GeoPoint(latitude.si, longitude.si, altitude.si + geoid_height), "base GNSS",
                stamp=min(s.stamp for s in samples),
                error=abs(accuracy.si) if accuracy is not None else None)
        samples, why = self._readings(self.ORIENTATION_KEYS,
                                      "rover GNSS heading and inclinometer")
        if why is not None:
            missing["orientation"] = why
        else:
            heading, roll, pitch = samples
            accuracy = self.device._fresh("rover_heading_accuracy")
            orientation = OrientationFix(
                Attitude.from_heading(heading.si, roll.si, -pitch.si),
                "rover GNSS heading + inclinometer", stamp=min(s.stamp for s in samples),
                heading_error=abs(accuracy.si) if accuracy is not None else None)
        return DevicePose(position, orientation, missing)


class TurretDevice(Device):
    """One turret (and its cover, GNSS and zoom nodes) on one CAN interface."""

    #: positions arrive as NOD broadcasts: joint_states follow each broadcast cycle
    streamed = True

    def post(self, moves: Moves, jogs: dict[str, float]) -> PostedWrite:
        """Set-points are single CAN frames; the turret answers none of them.
        Written from the caller's thread, with no answer to settle."""
        return self.write_now(moves, jogs)

    def __init__(
        self, client: TurretClient, settings: TurretSettings,
        publish_rate: Callable[[], float], log: Logger | None = None,
    ) -> None:
        super().__init__()
        if len(settings.joint_names) != len(AXES):
            raise InvalidRequest(f"the turret has exactly two joints (yaw, pitch), got "
                                 f"{list(settings.joint_names)}")
        self.settings = settings
        self.publish_rate = publish_rate
        self.log: Logger = log or logging.getLogger("canaero_turret_driver.device")
        self.client = client
        self.client.on_sample = self._on_sample
        self.client.on_link = self._on_link
        self.axis_of = dict(zip(settings.joint_names, AXES, strict=True))
        self.joint_of = {axis: joint for joint, axis in self.axis_of.items()}
        self._cycle: set[str] = set()
        self._latest: JointSample | None = None
        self._speed_warned = False
        self._tis_refusal_logged = False
        self._published: dict[str, float] = {}  # reading -> arrival of the last one handed out
        self.presets = TurretPresets(self)
        self.capabilities.presets = self.presets
        self.capabilities.status = TurretStatus(self)
        self.capabilities.geolocation = TurretGeolocation(self)

    # ------------------------------------------------------------------ conversion
    def _direction(self, axis: str) -> float:
        return float(self.settings.yaw_direction if axis == "yaw"
                     else self.settings.pitch_direction)

    def _to_device(self, axis: str, value: float) -> float:
        """An SI value (rad, rad/s) of a joint in REP-103 direction, in the ICD's degrees
        and the device's own direction: the one conversion of commands."""
        return math.degrees(value * self._direction(axis))

    def _position_setpoint(self, axis: str, position: float) -> float:
        """The position set-point in degrees, refused outside the ICD's -180..180."""
        degrees = self._to_device(axis, position)
        if not abs(degrees) <= ICD_POSITION_LIMIT_DEG + 1e-9:
            raise CommandError(f"{axis} position {position:.4f} rad is outside the "
                               f"device range -pi..pi")
        return max(-ICD_POSITION_LIMIT_DEG, min(ICD_POSITION_LIMIT_DEG, degrees))

    def _joint_value(self, axis: str, key: str) -> float | None:
        """The SI value of `<axis>_<key>` in REP-103 direction (None: not received)."""
        sample = self.client.latest(f"{axis}_{key}")
        if sample is None or sample.si is None:
            return None
        return sample.si * self._direction(axis)

    # ------------------------------------------------------------------ link
    def open(self) -> DeviceInfo:
        """Open the interface, identify the turret (IDS) and ask for the intervals (TIS).

        On failure the controller calls close() and tries again every reconnect_period.
        """
        client = self.client
        self._cycle.clear()
        client.open()
        info = client.identify()
        refused = client.request_intervals(self.interval_requests())
        if refused and not self._tis_refusal_logged:
            self._tis_refusal_logged = True
            self.log.warning(
                f"the turret refused TIS for {', '.join(sorted(refused))}: rate and staleness "
                "checks follow the intervals it actually sends (see /diagnostics "
                "'transmission intervals')")
        node = client.config.turret_node_id
        return DeviceInfo(
            model="CANaerospace turret", serial_number=f"node {node}",
            firmware_version=f"hw {info.hardware_revision} sw {info.software_revision}",
            hardware_id=f"canaerospace node {node} on {self.description()}")

    def close(self) -> None:
        self.client.close()

    def description(self) -> str:
        return self.client.description

    def link_healthy(self) -> bool:
        """The interface is open and the turret node is talking (else LinkError with why)."""
        client = self.client
        if not client.connected:
            raise LinkError(client.last_link_error or f"CAN interface {self.description()} "
                            "closed")
        if client.node_silent():
            node = client.config.turret_node_id
            seen = client.node_last_seen(node)
            silent_for = "" if seen is None else f" for {time.monotonic() - seen:.1f} s"
            others = client.frames_since_seen(node)
            heard = (f"{others} other CAN frames arrived meanwhile; data frames from a node "
                     f"id other than turret_node_id {node} on this connection: "
                     f"{client.counters.foreign_node}" if others
                     else f"no CAN frames on {self.description()}")
            raise LinkError(f"turret node {node} silent{silent_for} ({heard})")
        return True

    def _on_link(self, up: bool, why: str) -> None:
        if not up:
            self.notify_data()  # wake the controller's device thread: it sees the link down

    def _on_sample(self, sample: Sample) -> None:
        """Wake the controller once both axes of a broadcast cycle are in.

        Runs on the client's receive thread. Yaw and pitch positions are separate frames;
        waking on the first would publish it and then hold the second for a publish
        period. If one axis goes quiet, the controller's wait times out and reads anyway.
        """
        if sample.key not in POSITION_KEYS:
            return
        self._cycle.add(sample.key)
        if self._cycle >= POSITION_KEYS:
            self._cycle.clear()
            self.notify_data()

    # ------------------------------------------------------------------ joints
    def read(self) -> JointSample | None:
        """Positions, velocities, motor currents and the status bytes' target bits.

        None while a position is missing or stale: a stale position is never published
        as current. `moving` comes from the status byte (target not reached, or jog);
        without a status byte the controller's speed rule applies.
        """
        client = self.client
        positions: dict[str, float] = {}
        velocities: dict[str, float] = {}
        efforts: dict[str, float] = {}
        moving: dict[str, bool] = {}
        stamp = 0.0
        for axis in AXES:
            joint = self.joint_of[axis]
            sample = client.latest(f"{axis}_position")
            position = self._joint_value(axis, "position")
            if sample is None or position is None or client.is_stale(f"{axis}_position"):
                return None
            positions[joint] = position
            stamp = max(stamp, sample.stamp)
            velocity = self._joint_value(axis, "velocity")
            velocities[joint] = math.nan if velocity is None else velocity
            current = client.latest(f"{axis}_current")
            if current is not None and current.si is not None:
                efforts[joint] = current.si
            status = client.latest(f"{axis}_status")
            if status is not None:
                moving[joint] = AxisStatus.decode(status.value).target != TargetState.REACHED
        if len(efforts) != len(positions):
            efforts = {}
        self._latest = JointSample(positions, velocities, efforts, stamp, moving)
        return self._latest

    def positions(self) -> dict[str, float]:
        """The joints' last read positions (REP-103, rad)."""
        sample = self._latest
        return dict(sample.positions) if sample else {}

    def move(self, moves: Moves) -> None:
        self._warn_speed_once(moves)
        setpoints = {self.axis_of[joint]: self._position_setpoint(self.axis_of[joint], position)
                     for joint, (position, _speed) in moves.items()}
        for axis, degrees in setpoints.items():
            self.client.move_to(axis, degrees)

    def move_relative(self, offsets: dict[str, float], moves: Moves) -> bool:
        """A relative move as the turret's relative set-points (6.1.4, ids 1302/1312).

        The targets were checked against the limits; the device gets the offsets
        themselves, so it moves by exactly that much from where it is (no round trip
        through a possibly older position sample).
        """
        self._warn_speed_once(moves)
        for joint, offset in offsets.items():
            axis = self.axis_of[joint]
            self.client.move_by(axis, self._to_device(axis, offset))
        return True

    def _warn_speed_once(self, moves: Moves) -> None:
        if self._speed_warned or all(speed is None for _, speed in moves.values()):
            return
        self._speed_warned = True
        self.log.warning("the turret's set-points have no speed field: moves use the "
                         "device's own profile (speed checked against velocity_max only)")

    def jog(self, velocities: dict[str, float]) -> None:
        for joint, velocity in velocities.items():
            axis = self.axis_of[joint]
            if velocity == 0.0:
                self.client.stop([axis])
            else:
                self.client.jog(axis, self._to_device(axis, velocity))

    def stop(self, joints: Sequence[str] | None = None) -> None:
        axes = list(AXES) if joints is None else [self.axis_of[j] for j in joints]
        self.client.stop(axes)

    def refusal(self, joints: Sequence[str]) -> str | None:
        """Refuse motion on an axis whose status byte says its drive is off or faulted."""
        client = self.client
        reasons = []
        for joint in joints:
            axis = self.axis_of.get(joint)
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
        return "; ".join(reasons) + "; ~/reset_faults or ~/set_actuator_mode enables it again"

    def reset_faults(self) -> str:
        """The ICD has no fault reset; re-sending the actuator mode re-initialises a drive."""
        client = self.client
        sent = []
        for axis in AXES:
            if self.settings.actuator_mode:
                mode = MODE_NAMES[self.settings.actuator_mode]
            else:  # the mode it reports (free run is 0: not a missing report)
                reported = self.reported_mode(axis)
                mode = ActuatorMode.AUTO_BRAKE if reported is None else reported
            client.set_actuator_mode(axis, mode)
            sent.append(f"{self.joint_of[axis]}={mode.name.lower()}")
        client.events.clear()
        return "actuator mode re-sent to re-initialise the drives (" + ", ".join(sent) + ")"

    # ------------------------------------------------------------------ rates
    def interval_requests(self) -> dict[str, int]:
        """TIS requests for a (re)connect: what joint_states needs, then the parameter.

        The ICD does not say how often a turret sends by default (a real one: 100 ms), so
        with `request_intervals` the positions and velocities are asked for at
        1/publish_rate; `transmission_intervals` entries override or add to that.
        """
        intervals: dict[str, int] = {}
        if self.settings.request_intervals:
            interval_ms = max(MIN_TIS_INTERVAL_MS, round(1000.0 / self.publish_rate()))
            intervals = {f"{axis}_{what}": interval_ms for axis in AXES
                         for what in ("position", "velocity")}
        intervals.update(self.settings.transmission_intervals)
        return intervals

    def expected_rate(self, publish_rate: float) -> float:
        """publish_rate, or the slower rate at which the turret sends both positions.

        Taken from the interval the turret accepted by TIS or, when it refused, the one
        observed on the bus; until that is known, publish_rate.
        """
        intervals = [self.client.interval_of(key) for key in sorted(POSITION_KEYS)]
        if any(interval is None or interval <= 0 for interval in intervals):
            return publish_rate
        return min(publish_rate, 1.0 / max(intervals))  # type: ignore[type-var]

    def set_intervals(self, intervals: dict[str, int]) -> None:
        """TIS now for each entry (a node's refusal raises with its reply)."""
        for key, interval in intervals.items():
            self.client.set_transmission_interval(key, interval)

    # ------------------------------------------------------------------ extras
    def apply_actuator_mode(self, wait: float = MODE_REPORT_WAIT_S) -> str:
        """Send the configured actuator mode to each axis that does not report it already.

        A mode command re-initialises a drive (the simulator does so; the ICD is silent),
        which would stop a move a previous node left running, and would quietly re-enable a
        drive that a fault disabled. So an axis that reports the configured mode (its status
        byte or its actuator mode state, fresh) is left alone; one that has not reported
        within ``wait`` s after the connect gets the command. '' in the settings: nothing.
        """
        if not self.settings.actuator_mode:
            return "no actuator_mode configured"
        mode = MODE_NAMES[self.settings.actuator_mode]
        deadline = time.monotonic() + wait
        while (any(self.reported_mode(axis) is None for axis in AXES)
               and time.monotonic() < deadline):
            time.sleep(0.02)
        sent, kept = [], []
        for axis in AXES:
            if self.reported_mode(axis) == mode:
                kept.append(self.joint_of[axis])
            else:
                self.client.set_actuator_mode(axis, mode)
                sent.append(self.joint_of[axis])
        parts = [f"actuator mode {self.settings.actuator_mode} sent to {', '.join(sent)}"
                 if sent else "", f"already reported by {', '.join(kept)}" if kept else ""]
        return "; ".join(part for part in parts if part)

    def reported_mode(self, axis: str) -> ActuatorMode | None:
        """The actuator mode ``axis`` reports: its actuator mode state, else the mode in its
        status byte (sent more often); None when neither is fresh."""
        for key in (f"{axis}_actuator_mode_state", f"{axis}_status"):
            sample = self.client.latest(key)
            if sample is None or self.client.is_stale(key):
                continue
            value = sample.value if key.endswith("_state") else \
                AxisStatus.decode(sample.value).actuator_mode
            if value in tuple(ActuatorMode):
                return ActuatorMode(value)
        return None

    def set_mode(self, text: str) -> str:
        """`~/set_actuator_mode`: "auto_brake" for both joints or "yaw=free_run, pitch=...".

        Every name is checked before anything is sent.
        """
        targets: list[tuple[str, str]] = []
        for part in text.strip().lower().replace(",", " ").split():
            joint, sep, mode = part.partition("=")
            if not sep:
                targets += [(j, joint) for j in self.settings.joint_names]
            elif joint not in self.axis_of:
                raise CommandError(f"unknown joint {joint!r}; joints: "
                                   f"{list(self.settings.joint_names)}")
            else:
                targets.append((joint, mode))
        if not targets:
            raise CommandError(f"give a mode: one of {sorted(MODE_NAMES)} (or joint=mode)")
        for _, mode in targets:
            if mode not in MODE_NAMES:
                raise CommandError(f"unknown actuator mode {mode!r}; modes: "
                                   f"{sorted(MODE_NAMES)}")
        for joint, mode in targets:
            self.client.set_actuator_mode(self.axis_of[joint], MODE_NAMES[mode])
        return "actuator mode " + ", ".join(f"{j}={m}" for j, m in targets)

    def switch(self, name: str, on: bool) -> str:
        """One of the periphery on/off commands (`SWITCHES`): cover, fan, heaters, charging."""
        if name not in SWITCHES:
            raise CommandError(f"unknown switch {name!r}; switches: {sorted(SWITCHES)}")
        getattr(self.client, SWITCHES[name])(bool(on))
        if name == "set_cover":
            return "cover " + ("opening" if on else "closing")
        return name.removeprefix("set_").replace("_", " ") + (" on" if on else " off")

    def node_ids(self) -> dict[str, int]:
        """The node-ids in use (NIS through device_command changes them)."""
        return {name: getattr(self.client.config, name) for name in NODE_ID_FIELDS}

    def device_command(self, command: str, args: Sequence[str]) -> tuple[str, list[str]]:
        """`~/device_command`: the node services by name; returns (message, results).

        identify [node-id] | set_interval <key> <ms> | upload <memid> <length> |
        download <memid> <hex> | set_node_id <new> [node-id] |
        store_configuration <security code> [node-id]. NIS and FPS need their opt-in in
        the client config, DDS (download) `allow_data_download`.
        """
        client = self.client
        args = list(args)
        command = command.strip()

        def number(text: str) -> int:
            try:
                return int(text, 0)
            except ValueError as exc:
                raise CommandError(f"{text!r} is not an integer") from exc

        if command == "identify":
            info = client.identify(number(args[0]) if args else None)
            return "IDS answered", [
                f"hardware_revision={info.hardware_revision}",
                f"software_revision={info.software_revision}",
                f"identifier_distribution={info.identifier_distribution}",
                f"header_type={info.header_type}"]
        if command == "set_interval":
            if len(args) != 2:
                raise CommandError("set_interval needs <data key> <ms>")
            client.set_transmission_interval(args[0], number(args[1]))
            return f"{args[0]} every {number(args[1])} ms", []
        if command == "set_node_id":
            if not args:
                raise CommandError("set_node_id needs <new node-id> [node-id]")
            node = number(args[1]) if len(args) > 1 else client.config.turret_node_id
            new_id = number(args[0])
            client.set_node_id(new_id, node)
            self.log.warning(
                f"node {node} now has node-id {new_id}; put it in the parameter file, and "
                "store it with store_configuration (FPS) to keep it after a power cycle")
            return f"node-id {node} changed to {new_id}", []
        if command == "upload":
            if len(args) != 2:
                raise CommandError("upload needs <memory id> <length in bytes>")
            data = client.upload(number(args[0]), number(args[1]))
            return f"{len(data)} bytes read from memory {number(args[0])} (DUS)", [data.hex()]
        if command == "download":
            if not self.settings.allow_data_download:
                raise DeviceRefused("data download (DDS) writes device memory and is "
                                    "disabled; set allow_data_download to use it")
            if len(args) != 2:
                raise CommandError("download needs <memory id> <hex bytes>")
            try:
                data = bytes.fromhex(args[1])
            except ValueError as exc:
                raise CommandError(f"{args[1]!r} is not hex bytes") from exc
            checksum = client.download(number(args[0]), data)
            return (f"{len(data)} bytes written to memory {number(args[0])} (DDS)",
                    [f"checksum={checksum}"])
        if command == "store_configuration":
            if not args:
                raise CommandError("store_configuration needs <security code>")
            client.store_configuration(number(args[0]), number(args[1]) if len(args) > 1
                                       else None)
            return "configuration stored in flash", []
        raise CommandError(f"unknown command {command!r}; commands: "
                           + ", ".join(DEVICE_COMMANDS))

    # ------------------------------------------------------------------ readings
    def _fresh(self, key: str) -> Sample | None:
        """The latest `key` sample if it is numeric and not stale, else None."""
        sample = self.client.latest(key)
        if sample is None or sample.si is None or self.client.is_stale(key):
            return None
        return sample

    def _unseen(self, name: str, sample: Sample) -> bool:
        """True once per arrival of `sample` under `name` (each reading is handed out once)."""
        if self._published.get(name) == sample.received:
            return False
        self._published[name] = sample.received
        return True

    def new_fix(self) -> GnssFix | None:
        """The base GNSS position if a new one arrived since the last call (stale: fresh
        False, so a consumer sees the fix go away)."""
        client = self.client
        latitude, longitude = client.latest("latitude"), client.latest("longitude")
        if latitude is None or longitude is None or latitude.si is None \
                or longitude.si is None or not self._unseen("fix", latitude):
            return None
        altitude = client.latest("altitude_msl")
        accuracy = client.latest("position_accuracy")
        return GnssFix(
            stamp=latitude.stamp, latitude=latitude.si, longitude=longitude.si,
            altitude=altitude.si if altitude is not None and altitude.si is not None
            else math.nan,
            accuracy=accuracy.si if accuracy is not None else None,
            fresh=not (client.is_stale("latitude") or client.is_stale("longitude")))

    def new_heading(self, key: str) -> Heading | None:
        """A fresh `rover_heading` or `global_yaw` not handed out before; the accuracy is
        the rover GNSS's (7.3.2) while that is fresh."""
        sample = self._fresh(key)
        if sample is None or not self._unseen(key, sample):
            return None
        accuracy = self._fresh("rover_heading_accuracy")
        return Heading(sample.stamp, sample.si, abs(accuracy.si) if accuracy else None)

    def new_utc(self) -> tuple[float, float] | None:
        """(arrival, UTC seconds) of a fresh base-GNSS time not handed out before."""
        sample = self.client.latest("utc_time")
        if sample is None or self.client.is_stale("utc_time") \
                or not self._unseen("utc_time", sample):
            return None
        return sample.stamp, float(sample.value)

    def inclination(self) -> Inclination | None:
        pitch, roll = self.client.latest("global_pitch"), self.client.latest("global_roll")
        if pitch is None or roll is None or self.client.is_stale("global_pitch"):
            return None
        return Inclination(pitch.stamp, roll.si, pitch.si)

    def zoom(self) -> float | None:
        """Camera0 zoom position (counts) while fresh."""
        sample = self._fresh("zoom_position")
        return None if sample is None else sample.si
