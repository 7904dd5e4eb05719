"""CANaerospace turret simulator: turret, cover, GNSS and zoom nodes on one CAN bus.

The model (`TurretSimulator`) turns received CAN frames into replies and produces the
periodic NOD broadcasts. It is reached in one of two ways:

* `BusSimRunner`: on any python-can bus (`virtual` inside one process for tests,
  `socketcan` on a vcan interface on a robot);
* `SlcanSession` behind the shared `PtySimServer`: the simulator speaks the slcan ASCII
  protocol (Lawicel) on a pseudo-terminal, so another process opens it with
  python-can's `slcan` interface (`channel=<pty path>`). This is how the node tests and
  `canaero_turret_sim` work on machines without SocketCAN.

Axes run on the shared trapezoidal model (`gimbal_driver_common.sim_motion`). Fault
injection (methods of `TurretSimulator`, and the shared control verbs of
`gimbal_driver_common.sim_control` on stdin and the `--control-port` console, see
`make_control`): silence the nodes or one node, lose or repeat NOD frames (message-code
gaps), malformed frames, EED events, axis drive faults, periphery faults; `drop` and
`garbage` cut the link or send garbage bytes.

Simulator-defined EED codes (the ICD defines none): see `EedCode`. Operation id = the
offending command (`Operation`), location id = 1 yaw, 2 pitch, 0 whole node.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import logging
import math
import os
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from enum import IntEnum

import can

from gimbal_driver_common.sim_control import (
    ControlClient,
    ControlError,
    ControlServer,
    SimControl,
    run_simulator,
)
from gimbal_driver_common.sim_motion import AxisMotion

from .protocol import nodeservice as ns
from .protocol.datatypes import DataType
from .protocol.eed import build_eed
from .protocol.errors import CodecError
from .protocol.identifiers import (
    BASE_GNSS_NODE_ID,
    COVER_NODE_ID,
    DEFAULT_ZOOM_POSITION_ID,
    ROVER_GNSS_NODE_ID,
    STOP_PITCH_BIT,
    STOP_YAW_BIT,
    TURRET_NODE_ID,
    ZOOM_NODE_ID,
    ActuatorMode,
    AxisStatus,
    CoverState,
    Direction,
    TargetState,
    identifier_table,
)
from .protocol.message import CanAerospaceMessage
from .protocol.sequencing import MessageCodeCounter
from .slcan import open_bus

LOG = logging.getLogger("canaero_turret_sim")

DEFAULT_FPS_SECURITY_CODE = 0x5A
YAW, PITCH = "yaw", "pitch"


class EedCode(IntEnum):
    """Error codes the simulator puts in EED messages."""

    COMMAND_REJECTED = 0x0001  # axis in free run or faulted
    WRONG_DATA_TYPE = 0x0002
    SETPOINT_OUT_OF_RANGE = 0x0003
    DRIVE_FAULT = 0x0010  # injected drive fault
    INJECTED = 0x00FF  # raw injected event


class Operation(IntEnum):
    NONE = 0
    POSITION = 1
    VELOCITY = 2
    RELATIVE = 3
    MODE = 4
    STOP = 5
    OTHER = 6


LOCATION = {YAW: 1, PITCH: 2}

#: set-point command (key after the axis name) -> (operation named in a refusal's EED, the
#: AxisModel motion it starts, whether the value must lie in the axis range)
SETPOINTS: dict[str, tuple[Operation, str, bool]] = {
    "position_setpoint": (Operation.POSITION, "move_to", True),
    "velocity_setpoint": (Operation.VELOCITY, "jog", False),
    "relative_setpoint": (Operation.RELATIVE, "move_by", False),
}
#: on/off controls (value 0 or 1) -> the simulator attribute they switch
SWITCHES = {"fan_control": "fan_on", "oes_heater_control": "oes_heater_on",
            "drives_heater_control": "drives_heater_on", "charging_control": "charging_on"}

# Default transmission intervals in ms (the ICD only fixes cover state = 100 ms). A real
# turret sends its positions and velocities every 100 ms until a master asks for more by
# TIS, so the simulator does the same; the slower ones are simulator choices.
DEFAULT_INTERVALS_MS: dict[str, int] = {
    "yaw_position": 100, "yaw_velocity": 100, "pitch_position": 100, "pitch_velocity": 100,
    "yaw_status": 100, "pitch_status": 100, "yaw_actuator_mode_state": 500,
    "pitch_actuator_mode_state": 500, "yaw_current": 200, "pitch_current": 200,
    "yaw_motor_temperature": 1000, "pitch_motor_temperature": 1000,
    "yaw_power_stage_temperature": 1000, "pitch_power_stage_temperature": 1000,
    "yaw_bus_voltage": 1000, "pitch_bus_voltage": 1000, "yaw_humidity": 1000,
    "pitch_humidity": 1000, "yaw_revolutions": 500, "pitch_revolutions": 500,
    "fan_state": 500, "case_temperature": 1000, "charging_current": 1000,
    "charging_state": 500, "oes_heater_state": 500, "drives_heater_state": 1000,
    "periphery_status": 200, "global_pitch": 200, "global_roll": 200,
    "cover_state": 100, "rover_heading": 200, "rover_heading_accuracy": 1000,
    "global_yaw": 200, "latitude": 500, "longitude": 500, "altitude_msl": 500,
    "position_accuracy": 1000, "utc_time": 1000, "zoom_position": 200,
}
MIN_INTERVAL_MS = 10
MAX_INTERVAL_MS = 10000


class AxisModel(AxisMotion):
    """One drive on the shared trapezoidal model (``AxisMotion``), in degrees.

    Positions are kept unwrapped; a continuous axis (yaw, no limits) reports them
    wrapped to -180..180 and counts revolutions, a limited axis (pitch) stops at its
    limits. ``mode`` is the drive's idle | position | velocity.
    """

    def __init__(self, name: str, max_velocity: float, acceleration: float,
                 min_position: float | None = None,
                 max_position: float | None = None) -> None:
        super().__init__(max_speed=max_velocity, acceleration=acceleration,
                         min_position=min_position, max_position=max_position)
        self.name = name
        self.actuator_mode: int = ActuatorMode.AUTO_BRAKE
        self.fault = False

    @property
    def max_velocity(self) -> float:
        return self.max_speed

    @property
    def mode(self) -> str:
        if self.target is not None:
            return "position"
        return "velocity" if self.jog_velocity is not None else "idle"

    @property
    def continuous(self) -> bool:
        return self.min_position is None

    @property
    def enabled(self) -> bool:
        return not self.fault and self.actuator_mode != ActuatorMode.FREE_RUN

    @property
    def reported_position(self) -> float:
        if self.continuous:
            return (self.position + 180.0) % 360.0 - 180.0
        return self.position

    @property
    def revolutions(self) -> int:
        return math.floor((self.position + 180.0) / 360.0) if self.continuous else 0

    @property
    def target_state(self) -> int:
        if self.mode == "velocity":
            return TargetState.JOG
        if self.mode == "position":
            return TargetState.NOT_REACHED
        return TargetState.REACHED if abs(self.velocity) < 1e-6 else TargetState.NOT_REACHED

    def in_range(self, position: float) -> bool:
        if self.continuous:
            return -180.0 <= position <= 180.0
        assert self.min_position is not None and self.max_position is not None
        return self.min_position <= position <= self.max_position

    def move_to(self, position: float, speed: float | None = None) -> None:
        """Absolute set-point; a continuous axis takes the short way round."""
        if self.continuous:
            position = self.position + (position - self.reported_position + 180.0) % 360.0 - 180.0
        super().move_to(position, speed)

    def move_by(self, delta: float) -> None:
        base = self.target if self.target is not None else self.position
        super().move_to(base + delta)  # a limited axis clamps to its limits

    def step(self, dt: float) -> bool:
        if dt <= 0:
            return False
        if not self.enabled:
            self.stop()  # a disabled drive brakes to rest and drops its set-point
        return super().step(dt)


@dataclass
class Memory:
    """A block of node memory reachable with DDS/DUS."""

    data: bytearray
    writable: bool


@dataclass
class _Download:
    node_id: int
    memory_id: int
    numbers: range  # the message codes the data messages must carry, in order
    received: int = 0
    data: bytearray = field(default_factory=bytearray)


SCRATCH_MEMORY_ID = 1  # 64 bytes of writable scratch memory in the turret node
IDENT_MEMORY_ID = 16  # read-only identification text


@dataclass
class SimConfig:
    turret_node_id: int = TURRET_NODE_ID
    zoom_position_id: int = DEFAULT_ZOOM_POSITION_ID
    fps_security_code: int = DEFAULT_FPS_SECURITY_CODE
    yaw_max_velocity: float = 60.0
    pitch_max_velocity: float = 40.0
    acceleration: float = 180.0
    pitch_min: float = -30.0
    pitch_max: float = 60.0
    hardware_revision: int = 2
    software_revision: int = 7
    latitude_deg: float = 48.1372
    longitude_deg: float = 11.5756
    altitude_m: float = 519.0
    pad_frames: bool = False
    # Answer every TIS with -6 (out of range), like a turret with fixed intervals.
    refuse_tis: bool = False
    # DDS/DUS data messages count from 0 (default) or 1 (the ICD does not say)
    transfer_first_number: int = ns.DEFAULT_FIRST_NUMBER
    intervals_ms: dict[str, int] = field(default_factory=lambda: dict(DEFAULT_INTERVALS_MS))


class TurretSimulator:
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
                return [self._frame(reply) for reply in self._service(message, channel)]
            ident = self._table.get(message.can_id)
            if ident is None or ident.direction is not Direction.COMMAND:
                return []
            self._command(ident.key, message)
            out, self._outbox = self._outbox, []
            return out

    def _command(self, key: str, message: CanAerospaceMessage) -> None:
        ident = self._table[message.can_id]
        if message.data_type != ident.data_type:
            self._eed(EedCode.WRONG_DATA_TYPE, Operation.OTHER, 0)
            return
        value = message.value
        self.received_commands.append((key, value))
        if self._is_silent(self.config.turret_node_id, self._clock()) and key != "cover_control":
            return
        handler = self._handlers.get(key)
        if handler is not None:
            handler(value)

    def _command_handlers(self) -> dict[str, Callable[[object], None]]:
        """Command key -> handler: the turret's commands as a table (ICD 6, 7)."""
        handlers: dict[str, Callable[[object], None]] = {
            "stop_actuators": self._stop_actuators,
            "remember_position": self._remember_position,
            "restore_position": self._restore_position,
            "cover_control": self._cover_control,
        }
        for axis in (YAW, PITCH):
            for kind, (operation, motion, ranged) in SETPOINTS.items():
                handlers[f"{axis}_{kind}"] = functools.partial(
                    self._setpoint, axis, operation, motion, ranged)
            handlers[f"{axis}_actuator_mode"] = functools.partial(self._actuator_mode, axis)
        for key, attribute in SWITCHES.items():
            handlers[key] = functools.partial(self._switch, attribute)
        return handlers

    def _setpoint(self, axis_name: str, operation: Operation, motion: str, ranged: bool,
                  value: object) -> None:
        """A position, velocity or relative set-point: refused (EED) by a disabled axis or
        for a value that is not finite (positions: outside the axis range)."""
        axis = self.axes[axis_name]
        if not self._accepts(axis, operation):
            return
        if not (isinstance(value, float) and math.isfinite(value)
                and (not ranged or axis.in_range(value))):
            self._eed(EedCode.SETPOINT_OUT_OF_RANGE, operation, LOCATION[axis_name])
            return
        getattr(axis, motion)(value)

    def _actuator_mode(self, axis_name: str, value: object) -> None:
        axis = self.axes[axis_name]
        if value not in tuple(ActuatorMode):
            self._eed(EedCode.SETPOINT_OUT_OF_RANGE, Operation.MODE, LOCATION[axis_name])
            return
        axis.actuator_mode = int(value)  # type: ignore[arg-type]
        axis.fault = False  # a mode command re-initialises the drive
        axis.stop()

    def _stop_actuators(self, value: object) -> None:
        bits = int(value)  # type: ignore[arg-type]
        for axis_name, bit in ((YAW, STOP_YAW_BIT), (PITCH, STOP_PITCH_BIT)):
            if bits & bit:
                self.axes[axis_name].stop()

    def _remember_position(self, value: object) -> None:
        if value == 1:
            self.saved_position = (self.axes[YAW].reported_position,
                                   self.axes[PITCH].reported_position)

    def _restore_position(self, value: object) -> None:
        if value != 1 or self.saved_position is None:
            return
        for name, target in zip((YAW, PITCH), self.saved_position, strict=True):
            if self._accepts(self.axes[name], Operation.POSITION):
                self.axes[name].move_to(target)

    def _cover_control(self, value: object) -> None:
        if value not in (0, 1):
            return
        target = CoverState.OPENED if value == 1 else CoverState.CLOSED
        if target != self.cover_state:
            self.cover_state = CoverState.MIDDLE
            self._cover_target = target
            self._cover_arrival = self._clock() + 1.0

    def _switch(self, attribute: str, value: object) -> None:
        if value in (0, 1):
            setattr(self, attribute, bool(value))

    def _accepts(self, axis: AxisModel, operation: int) -> bool:
        if axis.enabled:
            return True
        self._eed(EedCode.COMMAND_REJECTED, operation, LOCATION[axis.name])
        return False

    def _nodes_addressed(self, node_id: int) -> list[int]:
        mine = list(self.node_ids.values())
        if node_id == ns.BROADCAST_NODE_ID:
            return mine
        return [node_id] if node_id in mine else []

    def _ids_of_node(self, node_id: int) -> set[int]:
        return {can_id for can_id in self._intervals if self._node_of(can_id) == node_id}

    def _service(self, request: CanAerospaceMessage,
                 channel: int) -> Iterable[CanAerospaceMessage]:
        now = self._clock()
        replies = []
        for node_id in self._nodes_addressed(request.node_id):
            if self._is_silent(node_id, now):
                continue
            if request.service_code in (ns.ServiceCode.DDS, ns.ServiceCode.DUS):
                replies.extend(self._transfer(node_id, request, channel))
                continue
            reply = self._service_for_node(node_id, request, channel)
            if reply is not None:
                replies.append(reply)
        return replies

    def _transfer(self, node_id: int, request: CanAerospaceMessage,
                  channel: int) -> list[CanAerospaceMessage]:
        """DDS (write) and DUS (read) of the simulated memories (see `MEMORIES`)."""
        service = ns.ServiceCode(request.service_code)
        if request.data_type == DataType.MEMID:
            memory_id, count = int(request.value), request.message_code  # type: ignore[arg-type]
            memory = (self.memories.get(memory_id)
                      if node_id == self.config.turret_node_id else None)
            if service == ns.ServiceCode.DDS:
                if memory is None or not memory.writable or not 1 <= count <= 255 \
                        or count * 4 > len(memory.data) + 3:
                    self._download = None
                    return [ns.long_response(node_id, service, ns.ServiceStatus.INVALID,
                                             request.message_code, channel)]
                self._download = _Download(
                    node_id, memory_id, ns.data_numbers(count, self.config.transfer_first_number))
                return [ns.long_response(node_id, service, ns.ServiceStatus.XON,
                                         request.message_code, channel)]
            if memory is None or not 1 <= count <= 255 or count * 4 > len(memory.data) + 3:
                return [ns.long_response(node_id, service, ns.ServiceStatus.ABORT,
                                         request.message_code, channel)]
            _, response_id = ns.service_channel_ids(channel)
            data = bytes(memory.data[:count * 4])
            replies = [ns.long_response(node_id, service, ns.ServiceStatus.OK,
                                        request.message_code, channel)]
            chunks = ns.transfer_messages(response_id, node_id, service, data,
                                          self.config.transfer_first_number)
            replies += chunks
            replies.append(ns.checksum_response(node_id, service, ns.block_checksum(data),
                                                chunks[-1].message_code, channel))
            return replies
        # a DDS data message
        download = self._download
        if service != ns.ServiceCode.DDS or download is None or download.node_id != node_id:
            return []
        value = request.value
        chunk = bytes(value if isinstance(value, tuple) else (value,))  # type: ignore[arg-type]
        if request.message_code != download.numbers[download.received] or \
                request.data_type not in (DataType.UCHAR, DataType.UCHAR2, DataType.UCHAR3,
                                          DataType.UCHAR4):
            self._download = None
            return [ns.long_response(node_id, service, ns.ServiceStatus.ABORT,
                                     request.message_code, channel)]
        download.data += chunk
        download.received += 1
        if download.received < len(download.numbers):
            return []
        self._download = None
        memory = self.memories[download.memory_id]
        memory.data[:len(download.data)] = download.data
        return [ns.checksum_response(node_id, service, ns.block_checksum(bytes(download.data)),
                                     request.message_code, channel)]

    def _service_for_node(self, node_id: int, request: CanAerospaceMessage,
                          channel: int) -> CanAerospaceMessage | None:
        service = request.service_code
        if service == ns.ServiceCode.IDS:
            info = ns.IdentificationInfo(self.config.hardware_revision,
                                         self.config.software_revision, 0, 0)
            return ns.ids_response(node_id, info, channel, request.message_code)
        if service == ns.ServiceCode.TIS:
            status = ns.ServiceStatus.OUT_OF_RANGE
            if request.data_type == DataType.SHORT2:
                can_id, interval = request.value  # type: ignore[misc]
                valid_interval = interval == 0 or MIN_INTERVAL_MS <= interval <= MAX_INTERVAL_MS
                if can_id in self._ids_of_node(node_id) and valid_interval \
                        and not self.config.refuse_tis:
                    self._intervals[can_id] = interval
                    self._next_due[can_id] = self._next_slot(interval)
                    status = ns.ServiceStatus.OK
            return ns.tis_response(node_id, status, channel)
        if service == ns.ServiceCode.FPS:
            if request.message_code != self.config.fps_security_code:
                return ns.fps_response(node_id, ns.ServiceStatus.INVALID_SECURITY_CODE, channel)
            self.stored_configuration = {"node_ids": dict(self.node_ids),
                                         "intervals": dict(self._intervals)}
            return ns.fps_response(node_id, ns.ServiceStatus.OK, channel)
        if service == ns.ServiceCode.NIS:
            new_id = request.message_code
            if not ns.NIS_MIN_NODE_ID <= new_id <= ns.NIS_MAX_NODE_ID:
                return ns.nis_response(node_id, ns.ServiceStatus.OUT_OF_RANGE, channel)
            reply = ns.nis_response(node_id, ns.ServiceStatus.OK, channel)
            for name, current in self.node_ids.items():
                if current == node_id:
                    self.node_ids[name] = new_id
                    if name == "turret":
                        self.config.turret_node_id = new_id
            return reply
        return None  # other services are not implemented by this device

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


# --- transports --------------------------------------------------------------------

class BusSimRunner:
    """Runs a simulator on a python-can bus (virtual, socketcan, ...) in a thread."""

    def __init__(self, simulator: TurretSimulator, bus: can.BusABC,
                 period: float = 0.005) -> None:
        self.simulator = simulator
        self.bus = bus
        self.period = period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="canaero-sim-bus",
                                        daemon=True)

    def start(self) -> BusSimRunner:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def _send(self, frames: Iterable[can.Message]) -> None:
        for frame in frames:
            try:
                self.bus.send(frame, timeout=0.1)
            except can.CanError as exc:
                LOG.warning("simulator could not send: %s", exc)

    def _run(self) -> None:
        next_poll = time.monotonic()
        while not self._stop.is_set():
            timeout = max(0.0, next_poll - time.monotonic())
            try:
                frame = self.bus.recv(timeout=timeout)
            except (can.CanError, OSError, ValueError) as exc:
                LOG.warning("simulator receive error: %s", exc)
                time.sleep(self.period)
                frame = None
            if frame is not None:
                self._send(self.simulator.handle(frame))
            now = time.monotonic()
            if now >= next_poll:
                next_poll = now + self.period
                self._send(self.simulator.poll(now))


def encode_slcan(frame: can.Message) -> bytes:
    """A frame as an slcan (Lawicel) ASCII record."""
    data = bytes(frame.data)
    if frame.is_extended_id:
        head = f"T{frame.arbitration_id:08X}{len(data)}"
    else:
        head = f"t{frame.arbitration_id:03X}{len(data)}"
    return (head + data.hex().upper()).encode("ascii") + b"\r"


class SlcanSession:
    """The adapter side of slcan: parses host commands, forwards frames both ways.

    Commands answered: O/L (open), C (close), S0-S8/sXXXX (bitrate), V/v/N (version,
    serial), F (status flags), Z/M/m/X/Q (accepted, no effect); tIIIL..., TIIIIIIIIL...
    (transmit). Unknown or malformed records get BEL (0x07), as a Lawicel adapter does.
    """

    MAX_LINE = 64

    def __init__(self, simulator: TurretSimulator) -> None:
        self.simulator = simulator
        self.is_open = False
        self._buffer = bytearray()
        self.rejected_records = 0

    def on_bytes(self, data: bytes) -> bytes:
        self._buffer.extend(data)
        out = bytearray()
        while True:
            end = self._buffer.find(b"\r")
            if end < 0:
                if len(self._buffer) > self.MAX_LINE:
                    self._buffer.clear()
                    self.rejected_records += 1
                    out += b"\a"
                break
            record = bytes(self._buffer[:end])
            del self._buffer[:end + 1]
            out += self._record(record.strip(b"\n"))
        return bytes(out)

    def _record(self, record: bytes) -> bytes:
        if not record:
            return b"\r"
        command, rest = chr(record[0]), record[1:]
        if command in "OL":
            self.is_open = True
            return b"\r"
        if command == "C":
            self.is_open = False
            return b"\r"
        if command in "SsZMmXQ":
            return b"\r"
        if command in "Vv":
            return b"V1013\r"
        if command == "N":
            return b"NSIM1\r"
        if command == "F":
            return b"F00\r"
        if command in "tT":
            frame = self._parse_frame(command, rest)
            if frame is None:
                self.rejected_records += 1
                return b"\a"
            replies = self.simulator.handle(frame) if self.is_open else []
            return b"z\r" + b"".join(encode_slcan(f) for f in replies)
        self.rejected_records += 1
        return b"\a"

    @staticmethod
    def _parse_frame(command: str, rest: bytes) -> can.Message | None:
        id_len = 3 if command == "t" else 8
        try:
            text = rest.decode("ascii")
            can_id = int(text[:id_len], 16)
            dlc = int(text[id_len])
            payload = bytes.fromhex(text[id_len + 1:id_len + 1 + 2 * dlc])
        except (ValueError, IndexError, UnicodeDecodeError):
            return None
        if dlc > 8 or len(payload) != dlc:
            return None
        return can.Message(arbitration_id=can_id, is_extended_id=command == "T", data=payload)

    def poll(self) -> bytes:
        frames = self.simulator.poll()
        if not self.is_open:
            return b""
        return b"".join(encode_slcan(frame) for frame in frames)


class SocketcandSession:
    """One TCP client of a socketcand-style bridge (the daemon's ASCII "rawmode" protocol).

    All sessions and the simulator share an in-process python-can `virtual` bus (`hub`),
    so the bridge behaves like a CAN bus: a frame a client sends reaches the simulator and
    every other client, and every broadcast reaches every client. python-can's
    `socketcand` interface connects with `channel=<name>, host=127.0.0.1, port=<port>`.

    Handshake: "< hi >" on connect, "< open <bus> >" -> "< ok >", "< rawmode >" -> "< ok >";
    then "< send <id> <len> <b0> ... >" from the client and "< frame <id> <sec.usec> <hex> >"
    to it. Frames start `RAW_SETTLE_S` after rawmode because python-can reads each
    handshake reply with a single recv() and must not get a frame glued to it.
    """

    RAW_SETTLE_S = 0.05
    MAX_RECORD = 200

    def __init__(self, hub_channel: str) -> None:
        self._bus = can.Bus(interface="virtual", channel=hub_channel)
        self._buffer = ""
        self._greeted = False
        self._opened = False
        self._raw_since: float | None = None
        self.rejected_records = 0

    def on_bytes(self, data: bytes) -> bytes:
        self._buffer += data.decode("ascii", "replace")
        out = []
        while True:
            start = self._buffer.find("<")
            end = self._buffer.find(">", start + 1) if start >= 0 else -1
            if start < 0 or end < 0:
                if start < 0 or len(self._buffer) - start > self.MAX_RECORD:
                    self._buffer = ""
                break
            record = self._buffer[start + 1:end].split()
            self._buffer = self._buffer[end + 1:]
            out.append(self._record(record))
        return "".join(out).encode("ascii")

    def _record(self, words: list[str]) -> str:
        if not words:
            return ""
        command = words[0]
        if command == "open" and len(words) == 2:
            self._opened = True
            return "< ok >"
        if command == "rawmode" and self._opened:
            self._raw_since = time.monotonic()
            return "< ok >"
        if command == "send" and self._raw_since is not None:
            frame = self._parse_send(words[1:])
            if frame is not None:
                with contextlib.suppress(can.CanError):
                    self._bus.send(frame)
                return ""
        self.rejected_records += 1
        return ""  # socketcand ignores what it does not understand

    @staticmethod
    def _parse_send(words: list[str]) -> can.Message | None:
        try:
            can_id, length = int(words[0], 16), int(words[1], 16)
            data = bytes(int(word, 16) for word in words[2:2 + length])
        except (ValueError, IndexError):
            return None
        if length > 8 or len(data) != length or can_id > 0x1FFFFFFF:
            return None
        return can.Message(arbitration_id=can_id, is_extended_id=len(words[0]) > 3,
                           data=data)

    def poll(self) -> bytes:
        if not self._greeted:
            self._greeted = True
            return b"< hi >"
        frames = []
        while True:
            frame = self._bus.recv(timeout=0)
            if frame is None:
                break
            frames.append(frame)
        if self._raw_since is None or time.monotonic() - self._raw_since < self.RAW_SETTLE_S:
            return b""
        return "".join(encode_socketcand(frame) for frame in frames).encode("ascii")

    def on_disconnect(self) -> None:
        self._bus.shutdown()


def encode_socketcand(frame: can.Message) -> str:
    can_id = f"{frame.arbitration_id:08X}" if frame.is_extended_id else \
        f"{frame.arbitration_id:03X}"
    stamp = frame.timestamp or time.time()
    return f"< frame {can_id} {stamp:.6f} {bytes(frame.data).hex().upper()} >"


# --- control verbs -----------------------------------------------------------------

FAULT_NAMES = ("drive", "case_sensor")


def make_control(simulator: TurretSimulator, link: object | None = None) -> SimControl:
    """The shared control verbs for the turret plus its own (``link``: the PtySimServer or
    TcpSimServer the simulator is reached through; None on a python-can bus).

    ``silence on|off`` silences every CAN node (the slcan adapter keeps answering, as a
    real adapter on a bus whose nodes went quiet); ``fault drive [yaw|pitch]`` trips a
    drive (EED + disabled axis), ``fault case_sensor`` the periphery's case sensor.
    Device verbs: node_silence, lose, repeat, malformed, eed.
    """

    def silence(silent: bool) -> None:
        simulator.silence_all(math.inf if silent else 0)

    def fault(args: list[str]) -> None:
        name = args[0].lower()
        if name == "drive":
            axes = args[1:] or [YAW]
            for axis in axes:
                if axis not in simulator.axes:
                    raise ControlError(f"no axis {axis!r}; axes {', '.join(simulator.axes)}")
                simulator.set_axis_fault(axis, True)
        elif name == "case_sensor":
            simulator.set_case_sensor_fault(True)
        else:
            raise ControlError(f"unknown fault {name!r}; names: {', '.join(FAULT_NAMES)}")

    def node_silence(args: list[str]) -> None:
        node, switch = args[0], (args[1].lower() if len(args) > 1 else "on")
        duration = 0.0 if switch == "off" else math.inf if switch == "on" else float(switch)
        nodes = list(simulator.node_ids) if node == "all" else [node]
        for name in nodes:
            simulator.set_silent(name, duration)

    def gnss(args: list[str]) -> None:
        if len(args) < 4:
            raise ControlError("gnss LAT LON ALT_MSL HEADING [ACCURACY_M]")
        latitude, longitude, altitude, heading = (float(a) for a in args[:4])
        with simulator._lock:
            simulator.latitude_deg, simulator.longitude_deg = latitude, longitude
            simulator.altitude_m, simulator.heading_deg = altitude, heading % 360.0
            if len(args) > 4:
                simulator.position_accuracy_m = float(args[4])

    def inclination(args: list[str]) -> None:
        if len(args) != 2:
            raise ControlError("inclination ROLL PITCH (deg)")
        with simulator._lock:
            simulator.inclination_deg = (float(args[0]), float(args[1]))

    def eed(args: list[str]) -> None:
        numbers = [int(a, 0) for a in args[:3]]
        simulator.emit_eed(*numbers, node=args[3] if len(args) > 3 else "turret")

    control = SimControl(
        "canaero_turret_sim", simulator.state, links=[link] if link is not None else [],
        silence=silence,
        no_nack="CANaerospace services have no negative acknowledge the turret sends; its "
                "error path is the EED event (fault, eed)",
        fault=fault, fault_names=FAULT_NAMES, clear_device=simulator.clear_faults)
    control.add_verb("node_silence", node_silence,
                     "node_silence NODE|all [on|off|SECONDS] "
                     "(NODE: turret, cover, rover_gnss, base_gnss, zoom)")
    control.add_verb("lose", lambda a: simulator.lose_frames(
        a[0], int(a[1]) if len(a) > 1 else 1), "lose KEY [COUNT] (e.g. yaw_position)")
    control.add_verb("repeat", lambda a: simulator.repeat_frames(
        a[0], int(a[1]) if len(a) > 1 else 1), "repeat KEY [COUNT]")
    control.add_verb("malformed", lambda a: simulator.send_malformed(int(a[0]) if a else 3),
                     "malformed [COUNT]")
    control.add_verb("eed", eed, "eed CODE [OPERATION] [LOCATION] [NODE]")
    control.add_verb("gnss", gnss, "gnss LAT LON ALT_MSL HEADING [ACCURACY_M]: base GNSS "
                     "position (deg, m above mean sea level) and rover heading (deg)")
    control.add_verb("inclination", inclination, "inclination ROLL PITCH: the base's "
                     "inclinometer (deg)")
    return control


__all__ = ["ControlClient", "ControlServer", "make_control"]


# --- command line ------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="canaero_turret_sim",
        description="CANaerospace turret simulator (turret, cover, GNSS and zoom nodes).")
    parser.add_argument("--transport", choices=("slcan-pty", "socketcand", "bus"),
                        default="slcan-pty",
                        help="slcan over a pseudo-terminal (default), a socketcand-style TCP "
                             "bridge on 127.0.0.1, or a python-can bus")
    parser.add_argument("--port", type=int, default=0,
                        help="TCP port of the socketcand bridge on 127.0.0.1 (0 = any)")
    parser.add_argument("--link", default=None,
                        help="path of the pty symlink for slcan-pty (default: a temp path)")
    parser.add_argument("--interface", default="virtual",
                        help="python-can interface for --transport bus (e.g. socketcan)")
    parser.add_argument("--channel", default="vcan0", help="python-can channel for bus")
    parser.add_argument("--control-port", type=int, default=0,
                        help="control console on 127.0.0.1 (0 = any free port, -1 = none); "
                             "the same verbs are read on stdin")
    parser.add_argument("--turret-node-id", type=int, default=TURRET_NODE_ID)
    parser.add_argument("--zoom-position-id", type=int, default=DEFAULT_ZOOM_POSITION_ID)
    parser.add_argument("--fps-security-code", type=int, default=DEFAULT_FPS_SECURITY_CODE)
    parser.add_argument("--refuse-tis", action="store_true",
                        help="answer every TIS request with -6 (fixed transmission intervals)")
    parser.add_argument("--transfer-first-number", type=int, choices=ns.FIRST_NUMBERS,
                        default=ns.DEFAULT_FIRST_NUMBER,
                        help="number of the first DDS/DUS data message (default 0)")
    parser.add_argument("--pad-frames", action="store_true",
                        help="send 8-byte frames (zero padded) like the ICD examples")
    parser.add_argument("--ready-file", default=None,
                        help="also write the JSON ready line to this file")
    parser.add_argument("-v", "--verbose", action="store_true")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    config = SimConfig(turret_node_id=args.turret_node_id,
                       zoom_position_id=args.zoom_position_id,
                       fps_security_code=args.fps_security_code, pad_frames=args.pad_frames,
                       refuse_tis=args.refuse_tis,
                       transfer_first_number=args.transfer_first_number)
    simulator = TurretSimulator(config)
    link = None
    runner = None
    bus = None
    if args.transport == "slcan-pty":
        from gimbal_driver_common.sim_server import PtySimServer

        link = PtySimServer(lambda: SlcanSession(simulator), link_path=args.link).start()
        endpoint = {"interface": "slcan", "channel": link.port_name, "pty": link.port_name}
    elif args.transport == "socketcand":
        from gimbal_driver_common.sim_server import TcpSimServer

        hub = f"canaero-sim-hub-{os.getpid()}"
        bus = can.Bus(interface="virtual", channel=hub)
        runner = BusSimRunner(simulator, bus).start()
        link = TcpSimServer(lambda: SocketcandSession(hub), port=args.port).start()
        endpoint = {"interface": "socketcand", "channel": "can0", "host": link.host,
                    "port": link.port}
    else:
        bus = open_bus(args.interface, args.channel)
        runner = BusSimRunner(simulator, bus).start()
        endpoint = {"interface": args.interface, "channel": args.channel}
    try:
        run_simulator(make_control(simulator, link), endpoint, args.control_port,
                      ready_file=args.ready_file)
    finally:
        if link is not None:
            link.stop()
        if runner is not None:
            runner.stop()
        if bus is not None:
            bus.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
