"""The turret as a gimbal_driver_common `Device`: `TurretClient` in joints, SI and REP-103.

No ROS here. The controller of gimbal_driver_common supervises the link (open, IDS,
reconnect every `reconnect_period`, link state); this adapter maps the turret's axes to
the configured joints, applies each axis' installation direction (`yaw_direction`,
`pitch_direction`: +1 or -1 between the device's count and REP-103), reads joint samples
from the client's broadcast cache and offers the turret's extras (actuator modes,
periphery switches) as methods the node calls through `controller.call`, and two parts
handed the client: `node_services` (node_services.py `TurretNodeServices`) and `readings`
(readings.py `TurretReadings`: GNSS, heading, inclination, zoom).

Capabilities (capabilities.py): preset slot 0 is the turret's own remember/restore
position (`TurretPresets.handles(0)`; the core's Motion keeps every other slot in the YAML
store), the base's pose from its GNSS nodes (`TurretGeolocation`), and `TurretStatus`
(status.py) decodes the status identifiers for /diagnostics and
~/status. The turret has no homing routine and no scans of its own.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from gimbal_driver_common.config import Logger
from gimbal_driver_common.controller import MOVING_SPEED
from gimbal_driver_common.device import Device, DeviceInfo, JointSample, Moves, PostedWrite
from gimbal_driver_common.errors import InvalidRequest, LinkError
from gimbal_driver_common.unanswered import ConnectReads

from .capabilities import TurretGeolocation, TurretPresets
from .client import AXES, CommandError, Sample, TurretClient
from .client_types import ServiceTimeout
from .node_services import TurretNodeServices
from .protocol.identifiers import ActuatorMode, AxisStatus, TargetState
from .protocol.nodeservice import IdentificationInfo
from .readings import TurretReadings, si
from .status import TurretStatus

MODE_NAMES = {mode.name.lower(): mode for mode in ActuatorMode}
ICD_POSITION_LIMIT_DEG = 180.0  # set-point range "-180 ÷ 180" (6.1.2, 6.1.1 pitch)
#: how long activation waits for both axes to report their actuator mode (the simulator's
#: status byte comes every 100 ms, its mode state every 500 ms)
MODE_REPORT_WAIT_S = 1.0
POSITION_KEYS = frozenset(f"{axis}_position" for axis in AXES)
MIN_TIS_INTERVAL_MS = 1  # TIS counts whole milliseconds
#: the on/off services of the node -> the client method that sends them
SWITCHES = {"set_cover": "set_cover", "set_fan": "set_fan", "set_oes_heater": "set_oes_heater",
            "set_drives_heater": "set_drives_heater", "set_charging": "set_charging"}


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
        #: best-effort connect requests the turret left unanswered (IDS)
        self.unanswered = ConnectReads(lambda text: self.log.warning(text))
        self.readings = TurretReadings(client)
        self.node_services = TurretNodeServices(
            client, lambda: settings.allow_data_download, lambda text: self.log.warning(text))
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
        value = si(sample)
        if value is None:
            return None
        return value * self._direction(axis)

    # ------------------------------------------------------------------ link
    def open(self) -> DeviceInfo:
        """Open the interface, identify the turret (IDS) and ask for the intervals (TIS).

        On failure the controller calls close() and tries again every reconnect_period.
        """
        client = self.client
        self._cycle.clear()
        client.open()
        info = self._identify()
        failed = client.services.request_intervals(self.interval_requests())
        if failed and not self._tis_refusal_logged:
            self._tis_refusal_logged = True
            self.log.warning(
                f"{client.intervals.failures()}: rate and staleness checks follow the "
                "intervals it actually sends (see /diagnostics 'transmission intervals')")
        node = client.config.turret_node_id
        firmware = ("unknown (IDS unanswered)" if info is None else
                    f"hw {info.hardware_revision} sw {info.software_revision}")
        return DeviceInfo(
            model="CANaerospace turret", serial_number=f"node {node}",
            firmware_version=firmware,
            hardware_id=f"canaerospace node {node} on {self.description()}")

    def _identify(self) -> IdentificationInfo | None:
        """IDS, best effort: the turret's broadcasts are what the node needs. Unanswered
        while they arrive, it is a WARN and a diagnostics key (:attr:`unanswered`) and
        connecting goes on; unanswered with the turret silent, the error names both."""
        client = self.client
        self.unanswered.clear()
        try:
            return client.services.identify()
        except ServiceTimeout as exc:
            node = client.config.turret_node_id
            if client.node_silent():
                raise ServiceTimeout(f"{exc}; no broadcast from turret node {node} either"
                                     ) from exc
            self.unanswered.missed("IDS", f"{exc} (turret node {node} broadcasts)")
            return None

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
            quiet = client.silent_for(node)
            silent_for = "" if quiet is None else f" for {quiet:.1f} s"
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
        """Hand the controller the sample once both axes of a broadcast cycle are in.

        Runs on the client's receive thread, where the controller reads and publishes the
        sample. Yaw and pitch positions are separate frames; publishing on the first
        would hold the second back for a publish period. If one axis goes quiet, the
        controller's device thread reads anyway once the stream is quiet.
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
        as current. `moving` comes from the status byte (target not reached, or jog), or
        the velocity report over the controller's speed threshold (the status byte may be
        older); without a status byte the controller's speed rule applies.
        """
        client = self.client
        positions: dict[str, float] = {}
        velocities: dict[str, float] = {}
        currents: dict[str, float] = {}
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
            current = si(client.latest(f"{axis}_current"))
            if current is not None:
                currents[joint] = current
            status = client.latest(f"{axis}_status")
            if status is not None:
                # the status byte comes every 100 ms by default, the velocity every 20 ms
                # (TIS): a "target reached" sent before a jog began must not read as at
                # rest while the velocity report shows the axis turning (a ~/stop called
                # just after a jog started answered success while pitch moved, in CI)
                reached = AxisStatus.decode(status.integer).target == TargetState.REACHED
                turning = velocity is not None and abs(velocity) > MOVING_SPEED
                moving[joint] = not reached or turning
        self._latest = JointSample(positions, velocities, currents, stamp, moving)
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
            status = AxisStatus.decode(sample.integer)
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
        known = self.client.intervals
        intervals = [known.interval_of(key) for key in sorted(POSITION_KEYS)]
        positive = [interval for interval in intervals if interval is not None and interval > 0]
        if len(positive) != len(intervals):
            return publish_rate
        return min(publish_rate, 1.0 / max(positive))

    def set_intervals(self, intervals: dict[str, int]) -> None:
        """TIS now for each entry (a node's refusal raises with its reply)."""
        for key, interval in intervals.items():
            self.client.services.set_transmission_interval(key, interval)

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
            value = sample.integer if key.endswith("_state") else \
                AxisStatus.decode(sample.integer).actuator_mode
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
