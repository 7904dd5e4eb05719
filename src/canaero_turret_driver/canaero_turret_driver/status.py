"""The turret's status identifiers as /diagnostics parts and ~/status fields (no ROS).

`TurretStatus` is the `StatusReport` capability of `TurretDevice`: the turret node's
frame counters and companion-node ages, one part per axis (status byte, temperatures,
voltages), periphery, message-code gaps, EED events, stale identifiers and the
transmission intervals in use. Thresholds come from the device's `TurretSettings`, which
the node updates at run time.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from gimbal_driver_common.device import AxisStateCode, StatusReport
from gimbal_driver_common.diagnostics import Level, StatusPart

from .client import AXES, TurretClient
from .protocol.datatypes import DataType
from .protocol.identifiers import ActuatorMode, AxisStatus, CoverState, decode_periphery
from .readings import si

if TYPE_CHECKING:
    from .device import TurretDevice

#: `monitored_nodes` names -> the node-id field of the client config
NODE_GROUPS = {
    "turret": "turret_node_id", "cover": "cover_node_id", "rover_gnss": "rover_gnss_node_id",
    "base_gnss": "base_gnss_node_id", "zoom": "zoom_node_id",
}
#: the ICD's default node-id of each identifier's sender -> its group
GROUP_OF_NODE_ID = {1: "turret", 2: "cover", 5: "rover_gnss", 6: "base_gnss", 7: "zoom"}
AXIS_KEYS = ("motor_temperature", "power_stage_temperature", "bus_voltage", "current",
             "humidity", "revolutions", "actuator_mode_state", "status")


class TurretStatus(StatusReport):
    """Decodes the client's cache; one instance per device."""

    def __init__(self, device: TurretDevice) -> None:
        self.device = device
        self._last_anomalies = 0
        self._eed_seen_count = 0
        self._eed_seen_at = -float("inf")

    @property
    def client(self) -> TurretClient:
        return self.device.client

    # ------------------------------------------------------------------ /diagnostics
    def parts(self) -> list[StatusPart]:
        client = self.client
        now = time.monotonic()
        parts = [self._node_part(client, now)]
        parts += [self._axis_part(client, axis) for axis in AXES]
        parts.append(self._periphery_part(client))
        parts.append(self._sequence_part(client))
        parts.append(self._events_part(client))
        parts.append(self._stale_part(client, now))
        parts.append(self._interval_part(client))
        return parts

    def _monitored_keys(self, client: TurretClient) -> list[str]:
        watched = self.device.settings.monitored_nodes
        return [ident.key for ident in client.data_identifiers()
                if ident.used and GROUP_OF_NODE_ID.get(ident.node_id or 0) in watched]

    def _interval_part(self, client: TurretClient) -> StatusPart:
        """Which transmission intervals the rate and staleness checks are based on.

        A turret that refuses TIS is not a fault (the ICD leaves intervals to the device):
        the part stays OK and says once, in its message, that the observed rates are used.
        """
        values = []
        for key in sorted(self.device.interval_requests()):
            accepted = client.intervals.accepted_interval_ms(key)
            observed = client.intervals.interval_of(key)
            if accepted is not None:
                values.append((key, f"{accepted} ms (accepted)"))
            elif observed is not None:
                values.append((key, f"{observed * 1000:.0f} ms (observed)"))
            else:
                values.append((key, "not received yet"))
        publish_rate = self.device.publish_rate()
        values.append(("expected_joint_states_hz",
                       f"{self.device.expected_rate(publish_rate):.2f}"))
        failures = client.intervals.failures()
        if failures:
            for key, reason in sorted(client.intervals.refused.items()):
                values.append((f"refused_{key}", reason))
            for key, reason in sorted(client.intervals.timed_out.items()):
                values.append((f"timed_out_{key}", reason))
            return StatusPart("transmission intervals", Level.OK,
                              f"{failures}: checks follow the intervals it sends", values)
        return StatusPart("transmission intervals", Level.OK,
                          "intervals accepted by the turret", values)

    def _node_part(self, client: TurretClient, now: float) -> StatusPart:
        counters = client.counters
        values = [("interface", self.device.description()),
                  ("turret_node_id", str(client.config.turret_node_id)),
                  ("frames", str(counters.frames)), ("malformed", str(counters.malformed)),
                  ("unknown_ids", str(counters.unknown)),
                  ("type_mismatch", str(counters.type_mismatch)),
                  ("foreign_node", str(counters.foreign_node)),
                  ("bus_errors", str(counters.bus_errors)),
                  ("interface_reopened", str(counters.reconnects))]
        if counters.last_malformed:
            values.append(("last_malformed", counters.last_malformed))
        for group, field_name in NODE_GROUPS.items():
            seen = client.node_last_seen(getattr(client.config, field_name))
            values.append((f"{group}_last_frame_age_s",
                           "never" if seen is None else f"{now - seen:.2f}"))
        unanswered = self.device.unanswered
        values += unanswered.diagnostics()
        if client.node_silent():
            return StatusPart("turret node", Level.ERROR, "turret node silent", values)
        if unanswered:  # best effort at connect: the broadcasts are what the node needs
            return StatusPart("turret node", Level.WARN,
                              f"turret node talking; {unanswered.summary()}", values)
        return StatusPart("turret node", Level.OK, "turret node talking", values)

    def _axis_part(self, client: TurretClient, axis: str) -> StatusPart:
        settings = self.device.settings
        values: list[tuple[str, str]] = []
        level, problems = Level.OK, []
        for key in AXIS_KEYS:
            sample = client.latest(f"{axis}_{key}")
            if sample is None or key == "actuator_mode_state":
                continue
            if key == "status":
                status = AxisStatus.decode(sample.integer)
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
            else:
                reading = si(sample)
                text = f"{reading:.2f}" if reading is not None else str(sample.value)
                values.append((key, text))
                if key.endswith("temperature") and reading is not None:
                    if reading > settings.temperature_error:
                        level = max(level, Level.ERROR)
                        problems.append(f"{key} {reading:.1f} degC")
                    elif reading > settings.temperature_warn:
                        level = max(level, Level.WARN)
                        problems.append(f"{key} {reading:.1f} degC")
        message = "; ".join(problems) if problems else "OK"
        return StatusPart(self.device.joint_of[axis], Level(level), message, values)

    def _periphery_part(self, client: TurretClient) -> StatusPart:
        values: list[tuple[str, str]] = []
        level, problems = Level.OK, []
        sample = client.latest("periphery_status")
        if sample is not None:
            values.append(("periphery_status", f"0x{sample.integer:08X}"))
            for key, is_set in decode_periphery(sample.integer).items():
                values.append((key, str(is_set)))
                if key == "case_temperature_sensor_fault" and is_set:
                    level = Level.WARN
                    problems.append("case temperature sensor fault")
        cover = client.latest("cover_state")
        if cover is not None:
            try:
                values.append(("cover", CoverState(cover.integer).name.lower()))
            except ValueError:
                values.append(("cover", f"undefined({cover.value})"))
        for key in ("case_temperature", "charging_current", "charging_state", "fan_state",
                    "oes_heater_state"):
            value = client.latest(key)
            if value is not None:
                values.append((key, f"{si(value):.2f}" if client.data_type_of(key)
                               == DataType.FLOAT else str(value.value)))
        case = si(client.latest("case_temperature"))
        if case is not None and case > self.device.settings.temperature_warn:
            level = Level.WARN
            problems.append(f"case temperature {case:.1f} degC")
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
        if self._event_recent(client):
            return StatusPart("emergency events", Level.WARN, latest.describe(), values)
        return StatusPart("emergency events", Level.OK, "no recent event", values)

    def _event_recent(self, client: TurretClient) -> bool:
        count = client.counters.eed
        now = time.monotonic()
        if count != self._eed_seen_count:
            self._eed_seen_count = count
            self._eed_seen_at = now
        return now - self._eed_seen_at <= self.device.settings.eed_hold

    def _stale_part(self, client: TurretClient, now: float) -> StatusPart:
        stale = [key for key in self._monitored_keys(client) if client.is_stale(key, now)]
        values = [("stale", ", ".join(stale))] if stale else []
        if stale:
            return StatusPart("data freshness", Level.WARN,
                              f"{len(stale)} identifier(s) stale: {', '.join(stale[:6])}"
                              + (" ..." if len(stale) > 6 else ""), values)
        return StatusPart("data freshness", Level.OK, "all monitored identifiers fresh", values)

    # ------------------------------------------------------------------ ~/status
    def mode(self) -> str:
        modes = []
        for axis in AXES:
            sample = self.client.latest(f"{axis}_actuator_mode_state")
            if sample is not None:
                try:
                    name = ActuatorMode(sample.integer).name.lower()
                except ValueError:
                    name = f"undefined({sample.value})"
                modes.append(f"{self.device.joint_of[axis]}={name}")
        return " ".join(modes)

    def axis_details(self, joint: str) -> dict[str, object]:
        sample = self.client.latest(f"{self.device.axis_of[joint]}_status")
        if sample is None:
            return {}
        status = AxisStatus.decode(sample.integer)
        details: dict[str, object] = {"calibrated": True}
        if not status.enabled:
            fault = status.actuator_mode != ActuatorMode.FREE_RUN
            details["state"] = AxisStateCode.FAULT if fault else AxisStateCode.DISABLED
            details["active_errors"] = ["drive_disabled"] if fault else ["free_run"]
        return details

    def errors(self) -> list[str]:
        client = self.client
        errors = []
        for axis in AXES:
            sample = client.latest(f"{axis}_status")
            if sample is not None:
                status = AxisStatus.decode(sample.integer)
                if not status.enabled and status.actuator_mode != ActuatorMode.FREE_RUN:
                    errors.append(f"{self.device.joint_of[axis]}_drive_disabled")
        periphery = client.latest("periphery_status")
        if periphery is not None and decode_periphery(periphery.integer)[
                "case_temperature_sensor_fault"]:
            errors.append("case_temperature_sensor_fault")
        if self._event_recent(client) and client.events:
            errors.append(client.events[-1].describe())
        return errors
