"""Turret simulator: the device model (state, NOD broadcasts, fault injection)."""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable

import can

from gimbal_driver_common.sim_requests import LateReplies, RequestFaults

from ..protocol import nodeservice as ns
from ..protocol.datatypes import DataType
from ..protocol.eed import build_eed
from ..protocol.errors import CodecError
from ..protocol.identifiers import (
    BASE_GNSS_NODE_ID,
    COVER_NODE_ID,
    ROVER_GNSS_NODE_ID,
    TURRET_NODE_ID,
    ZOOM_NODE_ID,
    AxisStatus,
    CoverState,
    Direction,
    identifier_table,
)
from ..protocol.message import CanAerospaceMessage
from ..protocol.sequencing import MessageCodeCounter
from .axis import (
    IDENT_MEMORY_ID,
    LOCATION,
    PITCH,
    SCRATCH_MEMORY_ID,
    YAW,
    AxisModel,
    EedCode,
    Memory,
    Operation,
    SimConfig,
    _Download,
)
from .handlers import CommandHandlers

LOG = logging.getLogger("canaero_turret_sim")

#: the node services the simulated nodes answer (``mute``/``delay`` take these names)
REQUESTS = tuple(service.name for service in (
    ns.ServiceCode.IDS, ns.ServiceCode.DDS, ns.ServiceCode.DUS, ns.ServiceCode.TIS,
    ns.ServiceCode.FPS, ns.ServiceCode.NIS))


class TurretSimulator(CommandHandlers):
    """The device model: thread-safe; `handle` for received frames, `poll` for time."""

    def __init__(self, config: SimConfig | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config or SimConfig()
        self._clock = clock
        self._lock = threading.RLock()
        self._table = identifier_table(self.config.zoom_position_id)
        self._key_to_id = {ident.key: can_id for can_id, ident in self._table.items()}
        self.axes = {
            YAW: AxisModel(YAW, self.config.yaw_max_velocity, self.config.acceleration),
            PITCH: AxisModel(PITCH, self.config.pitch_max_velocity, self.config.acceleration,
                             self.config.pitch_min, self.config.pitch_max),
        }
        self.node_ids = {
            "turret": self.config.turret_node_id, "cover": COVER_NODE_ID,
            "rover_gnss": ROVER_GNSS_NODE_ID, "base_gnss": BASE_GNSS_NODE_ID,
            "zoom": ZOOM_NODE_ID,
        }
        self.fan_on = False
        self.oes_heater_on = False
        self.drives_heater_on = False
        self.charging_on = False
        self.case_sensor_fault = False
        self.free_run_button = False
        self.cover_state = CoverState.CLOSED
        self._cover_target: int | None = None
        self._cover_arrival = 0.0
        self.saved_position: tuple[float, float] | None = None
        self.zoom_position = 2500  # Camera0 zoom, LONG counts (ICD 7.5.1)
        # GNSS and inclinometer (the `gnss` and `inclination` verbs set them): the base
        # GNSS position (7.4), the rover GNSS heading and its accuracy (7.3), and the
        # base's inclinometer roll and pitch (7.1.31-32), in the ICD's units
        self.latitude_deg = self.config.latitude_deg
        self.longitude_deg = self.config.longitude_deg
        self.altitude_m = self.config.altitude_m
        self.position_accuracy_m = 1.5
        self.heading_deg = 123.45678
        self.heading_accuracy_deg = 0.25
        self.inclination_deg = (-0.8, 1.5)  # (roll, pitch)
        self.stored_configuration: dict[str, object] | None = None
        self.received_commands: list[tuple[str, object]] = []
        self.malformed_received = 0
        # schedule: can_id -> (interval ms, next due time)
        self._intervals: dict[int, int] = {}
        self._next_due: dict[int, float] = {}
        now = self._clock()
        for key, interval in self.config.intervals_ms.items():
            can_id = self._key_to_id[key]
            self._intervals[can_id] = interval
            self._next_due[can_id] = now
        self._codes = MessageCodeCounter()
        self._last_step = now
        self._start = now
        # faults
        self._silent_until: dict[int, float] = {}
        self._lose: dict[int, int] = {}
        self._repeat: dict[int, int] = {}
        self._malformed_pending = 0
        self._outbox: list[can.Message] = []
        #: node services never answered (``mute``: received, dropped) or answered late
        #: (``delay``: the responses wait in ``_late`` for :meth:`poll`), by service name
        self.request_faults = RequestFaults()
        self._late: LateReplies[tuple[int, can.Message]] = LateReplies(clock)
        self.memories: dict[int, Memory] = {  # turret node memories by MEMID
            SCRATCH_MEMORY_ID: Memory(bytearray(64), writable=True),
            IDENT_MEMORY_ID: Memory(bytearray(b"CANAERO-TURRET-SIM hw2 sw7\0"),
                                              writable=False),
        }
        self._download: _Download | None = None
        self._handlers = self._command_handlers()

    # --- helpers -----------------------------------------------------------------

    def _frame(self, message: CanAerospaceMessage) -> can.Message:
        return can.Message(arbitration_id=message.can_id, is_extended_id=False,
                           data=message.to_bytes(pad=self.config.pad_frames))

    def _is_silent(self, node_id: int, now: float) -> bool:
        return self._silent_until.get(node_id, 0.0) > now

    def _node_of(self, can_id: int) -> int:
        ident = self._table[can_id]
        assert ident.node_id is not None
        return self.config.turret_node_id if ident.node_id == TURRET_NODE_ID else ident.node_id

    def _eed(self, code: int, operation: int, location: int,
             node_id: int | None = None) -> None:
        node = self.config.turret_node_id if node_id is None else node_id
        can_id = node if 0 < node <= 127 else 127
        message = build_eed(can_id, node, code, operation, location,
                            self._codes.next(can_id))
        if not self._is_silent(node, self._clock()):
            self._outbox.append(self._frame(message))

    # --- values --------------------------------------------------------------------

    def _value(self, key: str, now: float) -> object:
        yaw, pitch = self.axes[YAW], self.axes[PITCH]
        elapsed = now - self._start
        axis = yaw if key.startswith("yaw") else pitch
        is_axis_key = key.startswith(("yaw_", "pitch_"))
        suffix = key.split("_", 1)[1] if is_axis_key else ""
        if key in ("yaw_position", "pitch_position"):
            return axis.reported_position
        if key in ("yaw_velocity", "pitch_velocity"):
            return axis.velocity
        if suffix == "motor_temperature":
            return 35.0 + 0.02 * abs(axis.velocity)
        if suffix == "power_stage_temperature":
            return 40.0 + 0.03 * abs(axis.velocity)
        if suffix == "actuator_mode_state":
            return int(axis.actuator_mode)
        if suffix == "bus_voltage":
            return 27.8
        if suffix == "current":
            return 0.3 + 0.02 * abs(axis.velocity)
        if suffix == "humidity":
            return 21.5
        if suffix == "revolutions":
            return axis.revolutions
        if suffix == "status":
            return AxisStatus.encode(axis.target_state, axis.actuator_mode, axis.enabled)
        values: dict[str, object] = {
            "fan_state": int(self.fan_on),
            "case_temperature": 31.0,
            "charging_current": 1.2 if self.charging_on else 0.0,
            "charging_state": int(self.charging_on),
            "oes_heater_state": int(self.oes_heater_on) | (int(self.oes_heater_on) << 1),
            "drives_heater_state": int(self.drives_heater_on),
            "periphery_status": self._periphery(),
            "global_pitch": self.inclination_deg[1] + (0.01 * math.sin(elapsed)
                                                        if self.inclination_deg[1] else 0.0),
            "global_roll": self.inclination_deg[0],
            "cover_state": int(self.cover_state),
            "rover_heading": round(self.heading_deg * 1e5),
            "rover_heading_accuracy": round(self.heading_accuracy_deg * 1e5),
            "global_yaw": self.heading_deg,
            "latitude": round(self.latitude_deg * 1e7),
            "longitude": round(self.longitude_deg * 1e7),
            "altitude_msl": round(self.altitude_m * 1000),
            "position_accuracy": round(self.position_accuracy_m * 1e4),
            "utc_time": int(time.time()),
            "zoom_position": self.zoom_position,
        }
        return values[key]

    def _periphery(self) -> int:
        bits = (int(self.fan_on) | int(self.oes_heater_on) << 1 | int(self.oes_heater_on) << 2
                | int(self.drives_heater_on) << 3 | int(self.free_run_button) << 4
                | int(self.charging_on) << 7 | int(self.case_sensor_fault) << 8)
        return bits

    # --- time ----------------------------------------------------------------------

    def poll(self, now: float | None = None) -> list[can.Message]:
        """Advance physics and return the frames due now (broadcasts, EED, faults)."""
        with self._lock:
            now = self._clock() if now is None else now
            dt = min(now - self._last_step, 0.2)
            self._last_step = now
            for axis in self.axes.values():
                axis.step(dt)
            if self._cover_target is not None and now >= self._cover_arrival:
                self.cover_state = CoverState(self._cover_target)
                self._cover_target = None
            out, self._outbox = self._outbox, []
            # late service responses go on the bus unless their node has fallen silent since
            out.extend(frame for node_id, frame in self._late.due(now)
                       if not self._is_silent(node_id, now))
            for can_id, interval in self._intervals.items():
                if interval <= 0 or now < self._next_due[can_id]:
                    continue
                due = self._next_due[can_id] + interval / 1000.0
                self._next_due[can_id] = due if due > now else now + interval / 1000.0
                out.extend(self._broadcast(can_id, now))
            out.extend(self._take_malformed())
            return out

    def _broadcast(self, can_id: int, now: float) -> list[can.Message]:
        ident = self._table[can_id]
        node_id = self._node_of(can_id)
        if self._is_silent(node_id, now):
            return []
        code = self._codes.next(can_id)
        if self._lose.get(can_id, 0) > 0:
            self._lose[can_id] -= 1
            return []
        message = CanAerospaceMessage.build(can_id, node_id, ident.data_type,
                                            self._value(ident.key, now), 0, code)
        frames = [self._frame(message)]
        if self._repeat.get(can_id, 0) > 0:
            self._repeat[can_id] -= 1
            frames.append(self._frame(message))
        return frames

    def _next_slot(self, interval_ms: int) -> float:
        """The next multiple of `interval_ms` since start: identifiers given the same interval
        by TIS go out in the same cycle, like a device scheduler with one time base (yaw and
        pitch positions of one cycle then arrive together, whatever the TIS order)."""
        if interval_ms <= 0:
            return self._clock()
        period = interval_ms / 1000.0
        elapsed = self._clock() - self._start
        return self._start + math.ceil(elapsed / period) * period

    def _take_malformed(self) -> list[can.Message]:
        frames = []
        node = self.config.turret_node_id
        patterns = [
            bytes((node, DataType.FLOAT, 0)),  # shorter than a header
            bytes((node, DataType.FLOAT, 0, 0, 0x41)),  # FLOAT with one data byte
            bytes((node, 0x70, 0, 0, 1, 2, 3, 4)),  # user-defined type on a FLOAT id
        ]
        ids = [self._key_to_id["yaw_position"], self._key_to_id["yaw_velocity"],
               self._key_to_id["pitch_position"]]
        while self._malformed_pending > 0:
            index = self._malformed_pending % len(patterns)
            frames.append(can.Message(arbitration_id=ids[index], is_extended_id=False,
                                      data=patterns[index]))
            self._malformed_pending -= 1
        return frames

    # --- received frames -----------------------------------------------------------

    def handle(self, frame: can.Message) -> list[can.Message]:
        """Process one received frame; returns the immediate replies."""
        if frame.is_error_frame or frame.is_remote_frame or frame.is_extended_id:
            return []
        try:
            message = CanAerospaceMessage.from_frame(frame.arbitration_id, frame.data)
        except CodecError as exc:
            self.malformed_received += 1
            LOG.debug("malformed frame ignored: %s", exc)
            return []
        with self._lock:
            service = ns.service_channel_of(message.can_id)
            if service is not None:
                channel, is_request = service
                if not is_request:
                    return []
                name = service_name(message.service_code)
                if self.request_faults.muted(name):
                    return []  # mute: received and dropped, never served or answered
                replies = list(self._service(message, channel))
                seconds = self.request_faults.delay_of(name)
                if seconds and replies:
                    self._late.hold([(reply.node_id, self._frame(reply)) for reply in replies],
                                    seconds)
                    return []
                return [self._frame(reply) for reply in replies]
            ident = self._table.get(message.can_id)
            if ident is None or ident.direction is not Direction.COMMAND:
                return []
            self._command(ident.key, message)
            out, self._outbox = self._outbox, []
            return out


    # --- fault injection -----------------------------------------------------------

    def _node_id(self, node: str | int) -> int:
        if isinstance(node, int):
            return node
        if node not in self.node_ids:
            raise ValueError(f"unknown node {node!r}; nodes: {', '.join(self.node_ids)}")
        return self.node_ids[node]

    def set_silent(self, node: str | int, duration: float = math.inf) -> None:
        """The node sends nothing and answers nothing for `duration` s (0 = resume)."""
        with self._lock:
            node_id = self._node_id(node)
            self._silent_until[node_id] = self._clock() + duration if duration > 0 else 0.0

    def silence_all(self, duration: float = math.inf) -> None:
        for node in self.node_ids:
            self.set_silent(node, duration)

    def lose_frames(self, key: str, count: int = 1) -> None:
        """Drop the next `count` broadcasts of `key` (their message codes are used up)."""
        with self._lock:
            self._lose[self._key_to_id[key]] = self._lose.get(self._key_to_id[key], 0) + count

    def repeat_frames(self, key: str, count: int = 1) -> None:
        """Send the next `count` broadcasts of `key` twice (same message code)."""
        with self._lock:
            can_id = self._key_to_id[key]
            self._repeat[can_id] = self._repeat.get(can_id, 0) + count

    def send_malformed(self, count: int = 3) -> None:
        with self._lock:
            self._malformed_pending += count

    def emit_eed(self, error_code: int, operation: int = 0, location: int = 0,
                 node: str | int = "turret") -> None:
        with self._lock:
            self._eed(error_code, operation, location, self._node_id(node))

    def set_axis_fault(self, axis: str, fault: bool = True) -> None:
        """A drive fault disables the axis (status bit 7 off) and sends an EED."""
        with self._lock:
            model = self.axes[axis]
            model.fault = fault
            if fault:
                model.stop()
                self._eed(EedCode.DRIVE_FAULT, Operation.NONE, LOCATION[axis])

    def set_case_sensor_fault(self, fault: bool = True) -> None:
        with self._lock:
            self.case_sensor_fault = fault

    def clear_faults(self) -> None:
        with self._lock:
            # the bus outlives the node: a service answer still held by ``delay`` would
            # answer the next node's request of that service (a CAN service response names
            # its service, not the request), as it did a muted IDS in a loaded CI run
            self._late.clear()
            self._silent_until.clear()
            self._lose.clear()
            self._repeat.clear()
            self._malformed_pending = 0
            self.case_sensor_fault = False
            for axis in self.axes.values():
                axis.fault = False

    def state(self) -> dict[str, object]:
        """Snapshot for tests and the control port."""
        with self._lock:
            return {
                "axes": {name: {**a.snapshot(), "position": a.reported_position,
                                "unwrapped_position": a.position,
                                "actuator_mode": int(a.actuator_mode),
                                "fault": a.fault, "revolutions": a.revolutions}
                         for name, a in self.axes.items()},
                "cover_state": int(self.cover_state), "fan_on": self.fan_on,
                "oes_heater_on": self.oes_heater_on, "charging_on": self.charging_on,
                "drives_heater_on": self.drives_heater_on,
                "saved_position": self.saved_position, "node_ids": dict(self.node_ids),
                "intervals_ms": {self._table[i].key: v for i, v in self._intervals.items()},
                "stored_configuration": self.stored_configuration is not None,
                "commands_received": len(self.received_commands),
                "recent_commands": [[key, value] for key, value in
                                    self.received_commands[-10:]],
                "malformed_received": self.malformed_received,
            }


def service_name(code: int) -> str:
    """A node service's name (``IDS``, ``TIS``, ...), or its number for one the ICD lacks."""
    try:
        return ns.ServiceCode(code).name
    except ValueError:
        return str(code)
