"""Turret simulator: the command handlers and the node services (ICD 6, 7)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable
from typing import SupportsInt

from gimbal_driver_common.sim_requests import RequestFaults

from ..protocol import nodeservice as ns
from ..protocol.datatypes import DataType
from ..protocol.identifiers import (
    STOP_PITCH_BIT,
    STOP_YAW_BIT,
    ActuatorMode,
    CoverState,
    Identifier,
)
from ..protocol.message import CanAerospaceMessage
from .axis import (
    LOCATION,
    MAX_INTERVAL_MS,
    MIN_INTERVAL_MS,
    PITCH,
    SETPOINTS,
    SWITCHES,
    YAW,
    AxisModel,
    EedCode,
    Memory,
    Operation,
    SimConfig,
    _Download,
)


def _integer(value: object) -> int:
    """A decoded integer value (its data type was checked against the command's or the
    service's); anything else raises TypeError, as ``int()`` of it did."""
    if not isinstance(value, SupportsInt):
        raise TypeError(f"an integer value expected, got {value!r}")
    return int(value)


class CommandHandlers:
    """Commands and node services of :class:`~.model.TurretSimulator`, a base of it whose
    state they read and change."""

    # The model's state and helpers the handlers use (TurretSimulator defines each).
    config: SimConfig
    axes: dict[str, AxisModel]
    node_ids: dict[str, int]
    cover_state: CoverState
    saved_position: tuple[float, float] | None
    stored_configuration: dict[str, object] | None
    received_commands: list[tuple[str, object]]
    memories: dict[int, Memory]
    _table: dict[int, Identifier]
    _handlers: dict[str, Callable[[object], None]]
    request_faults: RequestFaults
    _intervals: dict[int, int]
    _next_due: dict[int, float]
    _cover_target: int | None
    _cover_arrival: float
    _download: _Download | None
    _clock: Callable[[], float]
    _eed: Callable[[int, int, int], None]
    _is_silent: Callable[[int, float], bool]
    _node_of: Callable[[int], int]
    _next_slot: Callable[[int], float]

    def _command(self, key: str, message: CanAerospaceMessage) -> None:
        ident = self._table[message.can_id]
        if message.data_type != ident.data_type:
            self._eed(EedCode.WRONG_DATA_TYPE, Operation.OTHER, 0)
            return
        value = message.value
        self.received_commands.append((key, value))
        if self._is_silent(self.config.turret_node_id, self._clock()) and key != "cover_control":
            return
        if self.request_faults.muted(key) or self.request_faults.ignored(key):
            return  # mute/ignore: received, not acted on (a command frame has no answer)
        handler = self._handlers.get(key)
        if handler is not None:
            handler(value)

    def command_names(self) -> list[str]:
        """The command keys ``mute``/``ignore`` take besides the node services (a command
        frame has no answer: ``delay`` of one holds nothing)."""
        return sorted(self._handlers)

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
        axis.actuator_mode = _integer(value)
        axis.fault = False  # a mode command re-initialises the drive
        axis.stop()

    def _stop_actuators(self, value: object) -> None:
        bits = _integer(value)
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
            memory_id, count = _integer(request.value), request.message_code
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
        chunk = bytes(value if isinstance(value, tuple) else (value,))
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
                value = request.value
                if not isinstance(value, tuple):  # SHORT2 decodes to (short, short)
                    raise TypeError(f"TIS carries {value!r}, not (identifier, interval)")
                can_id, interval = value
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
