"""Turret session on a python-can bus: receive thread, value cache, commands, node services.

No ROS here. The client owns one `can.BusABC` (any python-can interface: socketcan on a
robot, slcan or virtual here). A receive thread decodes every frame, keeps the latest
value of each data identifier with its arrival time, tracks message-code sequences per
identifier, collects EED events and answers pending node-service requests. Interface
errors (bus-off error frames, a vanished adapter, a failing send) close the bus and end
the receive thread; `connected` turns False and whoever supervises the link (the
controller of gimbal_driver_common, through `TurretDevice`) closes and reopens it.

Units: the identifier table converts each value to SI (rad, rad/s, ...) in the device's
own direction; `TurretDevice` maps the axes to joints and applies the installation's
REP-103 direction. Errors are the core's hierarchy (`gimbal_driver_common.errors`).

Frames with an id not in the identifier table (including the out-of-scope functions)
are counted as unknown and otherwise ignored.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import can

from gimbal_driver_common import errors

from .protocol import nodeservice as ns
from .protocol.datatypes import DataType
from .protocol.eed import EmergencyEvent, decode_eed, is_eed
from .protocol.errors import CodecError
from .protocol.identifiers import (
    BASE_GNSS_NODE_ID,
    BY_KEY,
    COVER_NODE_ID,
    DEFAULT_ZOOM_POSITION_ID,
    MASTER_NODE_ID,
    ROVER_GNSS_NODE_ID,
    STOP_PITCH_BIT,
    STOP_YAW_BIT,
    TURRET_NODE_ID,
    ZOOM_NODE_ID,
    ActuatorMode,
    Direction,
    Identifier,
    identifier_table,
)
from .protocol.message import CanAerospaceMessage
from .protocol.sequencing import MessageCodeCounter, MessageCodeTracker, SequenceEvent
from .slcan import open_bus

LOG = logging.getLogger("canaero_turret_driver.client")

AXES = ("yaw", "pitch")
CAN_ERR_BUSOFF = 0x40  # SocketCAN error-frame class bit for bus-off
ICD_POSITION_LIMIT_DEG = 180.0  # set-point range "-180 ÷ 180" (6.1.2, 6.1.1 pitch)


class TurretError(errors.GimbalError):
    """Base of the client's errors; the message is meant for a person."""


class LinkError(TurretError, errors.LinkError):
    """The CAN interface is not open or failed while sending."""


class CommandError(TurretError, errors.InvalidRequest):
    """A command was refused before anything was sent."""


class ServiceError(TurretError):
    """A node-service request failed (no response, or a negative status)."""


class ServiceRefused(ServiceError, errors.DeviceRefused):
    """A node answered a node-service request with a negative status."""


class ServiceTimeout(ServiceError, errors.DeviceTimeout):
    """A node did not answer a node-service request (or stopped answering mid-transfer)."""


class NotAllowedError(TurretError, errors.DeviceRefused):
    """A persistent or identity-changing service was not enabled by configuration."""


@dataclass
class ClientConfig:
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: int | None = None
    bus_options: dict[str, object] = field(default_factory=dict)
    client_node_id: int = MASTER_NODE_ID
    turret_node_id: int = TURRET_NODE_ID
    cover_node_id: int = COVER_NODE_ID
    rover_gnss_node_id: int = ROVER_GNSS_NODE_ID
    base_gnss_node_id: int = BASE_GNSS_NODE_ID
    zoom_node_id: int = ZOOM_NODE_ID
    zoom_position_id: int = DEFAULT_ZOOM_POSITION_ID
    service_channel: int = 0
    service_timeout: float = ns.SERVICE_RESPONSE_TIMEOUT_S
    service_attempts: int = 3
    stale_timeout: float = 1.0
    node_timeout: float = 1.0
    # Drop the interface (connected -> False, the supervisor reopens it) when no frame at
    # all arrived for this long (0 = never). Some transports (a socketcand TCP link that
    # the peer closed, a wedged USB adapter) go quiet instead of raising; a CAN bus with a
    # broadcasting turret is never quiet.
    reopen_after_silence: float = 0.0
    pad_frames: bool = False
    allow_node_id_change: bool = False
    allow_flash_programming: bool = False
    # DDS/DUS data messages count from 0 or from 1 (the ICD does not say, see nodeservice)
    transfer_first_number: int = ns.DEFAULT_FIRST_NUMBER


@dataclass(frozen=True)
class Sample:
    """The latest value of one data identifier."""

    key: str
    value: object  # as decoded (device units)
    si: float | None  # SI value (the device's own direction) for numeric values
    stamp: float  # wall-clock time of arrival (for ROS headers)
    received: float  # monotonic time of arrival (for staleness)
    message_code: int
    node_id: int


@dataclass
class Counters:
    frames: int = 0
    malformed: int = 0
    unknown: int = 0
    foreign_node: int = 0
    type_mismatch: int = 0
    eed: int = 0
    bus_errors: int = 0
    reconnects: int = 0
    last_malformed: str = ""


class _Exchange:
    """Responses to one outstanding node-service request, in arrival order."""

    def __init__(self, request: CanAerospaceMessage) -> None:
        self.request = request
        self._messages: deque[CanAerospaceMessage] = deque()
        self._condition = threading.Condition()
        self._aborted = False

    def add(self, message: CanAerospaceMessage) -> None:
        with self._condition:
            self._messages.append(message)
            self._condition.notify_all()

    def abort(self) -> None:
        with self._condition:
            self._aborted = True
            self._condition.notify_all()

    def wait_next(self, timeout: float) -> CanAerospaceMessage | None:
        with self._condition:
            self._condition.wait_for(lambda: self._messages or self._aborted, timeout)
            return self._messages.popleft() if self._messages else None

    def drain(self) -> list[CanAerospaceMessage]:
        with self._condition:
            messages = list(self._messages)
            self._messages.clear()
            return messages


def _default_bus_factory(config: ClientConfig) -> can.BusABC:
    """python-can's bus for the configured interface (slcan: the chunked reader)."""
    kwargs = dict(config.bus_options)
    if config.bitrate:
        kwargs["bitrate"] = config.bitrate
    return open_bus(config.interface, config.channel, **kwargs)


class TurretClient:
    """A CANaerospace master talking to the turret and its companion nodes."""

    def __init__(self, config: ClientConfig | None = None,
                 bus_factory: Callable[[ClientConfig], can.BusABC] | None = None) -> None:
        self.config = config or ClientConfig()
        self._bus_factory = bus_factory or _default_bus_factory
        self._table = identifier_table(self.config.zoom_position_id)
        self._bus: can.BusABC | None = None
        self._bus_lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._service_lock = threading.Lock()
        self._cache_lock = threading.Lock()
        self._cache: dict[str, Sample] = {}
        self._node_seen: dict[int, float] = {}
        self._frames_at_seen: dict[int, int] = {}  # counters.frames when the node last spoke
        self._intervals_ms: dict[str, int] = {}  # TIS intervals the nodes accepted
        self.refused_intervals: dict[str, str] = {}  # key -> why TIS was refused
        self._observed_interval: dict[str, float] = {}
        self._exchange: _Exchange | None = None
        self._codes = MessageCodeCounter()
        self.sequences = MessageCodeTracker()
        self.counters = Counters()
        self.events: deque[EmergencyEvent] = deque(maxlen=50)
        self.last_link_error = ""
        self._garbled_in_row = 0
        self._last_frame = time.monotonic()
        self._opened_before = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.on_sample: Callable[[Sample], None] | None = None
        self.on_sequence: Callable[[str, SequenceEvent, int], None] | None = None
        self.on_link: Callable[[bool, str], None] | None = None

    # --- link ---------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        return self._bus is not None

    @property
    def description(self) -> str:
        return f"{self.config.interface}:{self.config.channel}"

    def open(self) -> None:
        """Open the CAN interface (raises LinkError) and start its receive thread.

        After the link dropped, call `close()` and then `open()` again: the client has no
        reconnect loop of its own (the controller's supervisor is the only one).
        """
        if self._bus is not None:
            return
        self._stop_thread()
        self._open_bus()
        if self._opened_before:
            self.counters.reconnects += 1
        self._opened_before = True
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, args=(self._bus,),
                                        name="canaero-reader", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the receive thread and release the interface. Safe to call twice."""
        self._stop_thread()
        self._drop_bus("closed", lost=False)

    def _stop_thread(self) -> None:
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)

    def _open_bus(self) -> None:
        try:
            bus = self._bus_factory(self.config)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            self.last_link_error = f"cannot open CAN interface {self.description}: {exc}"
            raise LinkError(self.last_link_error) from exc
        with self._bus_lock:
            self._bus = bus
        self._last_frame = time.monotonic()
        self.sequences.reset()
        self.last_link_error = ""
        LOG.info("CAN interface %s open", self.description)
        if self.on_link is not None:
            self.on_link(True, f"CAN interface {self.description} open")

    def _drop_bus(self, reason: str, lost: bool = True) -> None:
        """Release the bus; `on_link(False, reason)` either way, a warning when `lost`."""
        with self._bus_lock:
            bus, self._bus = self._bus, None
        if bus is None:
            return
        with contextlib.suppress(Exception):
            bus.shutdown()
        self.last_link_error = reason
        exchange = self._exchange
        if exchange is not None:
            exchange.abort()  # wake a waiting service request; it finds no response
        if lost:
            LOG.warning("CAN interface %s lost: %s", self.description, reason)
        if self.on_link is not None:
            self.on_link(False, reason)

    def _run(self, bus: can.BusABC) -> None:
        """Receive on `bus` until it is dropped (link lost or closed), then end."""
        while not self._stop.is_set() and self._bus is bus:
            try:
                frame = bus.recv(timeout=0.05)
            except (ValueError, IndexError) as exc:
                # slcan/serial adapters raise these on garbled ASCII records.
                self._garbled(bus, exc)
                continue
            except (can.CanError, OSError) as exc:
                if isinstance(exc.__cause__, ValueError | IndexError):
                    # python-can wraps an undecodable byte sequence in CanOperationError.
                    self._garbled(bus, exc.__cause__)
                    continue
                self._drop_bus(f"receive failed: {exc}")
                continue
            except Exception as exc:  # noqa: BLE001 - a driver thread must not die
                self._drop_bus(f"receive failed unexpectedly: {exc!r}")
                continue
            if frame is None:
                quiet = time.monotonic() - self._last_frame
                if 0 < self.config.reopen_after_silence < quiet:
                    self._drop_bus(f"no CAN frame for {quiet:.1f} s: the interface looks dead")
                continue
            self._last_frame = time.monotonic()
            self._garbled_in_row = 0
            try:
                self._dispatch(frame)
            except Exception:  # a bad callback must not end the receive thread
                LOG.exception("error while handling a CAN frame")

    # --- receive ------------------------------------------------------------------

    def _garbled(self, bus: can.BusABC, exc: BaseException) -> None:
        """Resynchronise after bytes the adapter could not parse.

        python-can's slcan keeps an undecodable partial record in its buffer (every later
        record then fails too), so the adapter's receive buffer is flushed; if records
        keep failing the interface is reopened.
        """
        self._malformed(f"garbled record from the adapter: {exc}")
        self._garbled_in_row += 1
        flush = getattr(bus, "flush", None)
        if callable(flush):
            with contextlib.suppress(Exception):
                flush()
        if self._garbled_in_row >= 20:
            self._garbled_in_row = 0
            self._drop_bus("the adapter keeps sending unreadable records")

    def _malformed(self, text: str) -> None:
        self.counters.malformed += 1
        self.counters.last_malformed = text
        LOG.debug("malformed: %s", text)

    def _expected_node(self, ident: Identifier) -> int:
        mapping = {
            TURRET_NODE_ID: self.config.turret_node_id,
            COVER_NODE_ID: self.config.cover_node_id,
            ROVER_GNSS_NODE_ID: self.config.rover_gnss_node_id,
            BASE_GNSS_NODE_ID: self.config.base_gnss_node_id,
            ZOOM_NODE_ID: self.config.zoom_node_id,
        }
        assert ident.node_id is not None
        return mapping[ident.node_id]

    def _dispatch(self, frame: can.Message) -> None:
        self.counters.frames += 1
        if frame.is_error_frame:
            self.counters.bus_errors += 1
            if frame.arbitration_id & CAN_ERR_BUSOFF:
                self._drop_bus("bus-off reported by the CAN controller")
            return
        if frame.is_extended_id or frame.is_remote_frame:
            self.counters.unknown += 1
            return
        try:
            message = CanAerospaceMessage.from_frame(frame.arbitration_id, frame.data)
        except CodecError as exc:
            self._malformed(str(exc))
            return
        now = time.monotonic()
        if is_eed(message.can_id):
            self._seen(message.node_id, now)
            try:
                event = decode_eed(message)
            except CodecError as exc:
                self._malformed(str(exc))
                return
            self.counters.eed += 1
            self.events.append(event)
            LOG.warning("%s", event.describe())
            return
        service = ns.service_channel_of(message.can_id)
        if service is not None:
            self._service_frame(message, now)
            return
        ident = self._table.get(message.can_id)
        if ident is None or ident.direction is not Direction.DATA:
            self.counters.unknown += 1
            return
        if message.node_id != self._expected_node(ident):
            self.counters.foreign_node += 1
            return
        self._seen(message.node_id, now)
        if message.data_type != ident.data_type:
            self.counters.type_mismatch += 1
            self._malformed(f"id {message.can_id} ({ident.key}) carries {message.type_name}, "
                            f"the ICD says {ident.data_type.name}")
            return
        event, missed = self.sequences.update((message.node_id, message.can_id),
                                              message.message_code)
        if event not in (SequenceEvent.FIRST, SequenceEvent.IN_ORDER) \
                and self.on_sequence is not None:
            self.on_sequence(ident.key, event, missed)
        if not event.accepted:
            return  # an old or duplicate value must not replace the newer one
        value = message.value
        sample = Sample(ident.key, value, self._to_si(ident, value), time.time(), now,
                        message.message_code, message.node_id)
        with self._cache_lock:
            previous = self._cache.get(ident.key)
            self._cache[ident.key] = sample
        if previous is not None:
            self._learn_interval(ident.key, now - previous.received)
        if self.on_sample is not None:
            self.on_sample(sample)

    def _to_si(self, ident: Identifier, value: object) -> float | None:
        if isinstance(value, bool) or not isinstance(value, int | float):
            return None
        return ident.to_si(value)

    def _service_frame(self, message: CanAerospaceMessage, now: float) -> None:
        exchange = self._exchange
        if exchange is not None and ns.is_response_to(exchange.request, message):
            self._seen(message.node_id, now)
            exchange.add(message)

    # --- cache --------------------------------------------------------------------

    def latest(self, key: str) -> Sample | None:
        with self._cache_lock:
            return self._cache.get(key)

    def snapshot(self) -> dict[str, Sample]:
        with self._cache_lock:
            return dict(self._cache)

    def _learn_interval(self, key: str, gap: float) -> None:
        """Track how often an identifier arrives (the ICD leaves intervals to the device).

        A smoothed inter-arrival time; gaps longer than 4x the estimate (an outage, a
        silence) do not inflate it.
        """
        estimate = self._observed_interval.get(key)
        if estimate is None:
            self._observed_interval[key] = gap
        elif gap <= 4.0 * estimate:
            self._observed_interval[key] = 0.8 * estimate + 0.2 * gap

    def stale_timeout_for(self, key: str) -> float:
        """`stale_timeout`, or 3 transmission intervals for slower identifiers.

        The interval is the one the node accepted by TIS; without one (never requested,
        or refused) it is the interval observed on the bus.
        """
        interval = self.interval_of(key)
        if interval is None:
            return self.config.stale_timeout
        return max(self.config.stale_timeout, 3.0 * interval)

    def age(self, key: str, now: float | None = None) -> float | None:
        sample = self.latest(key)
        if sample is None:
            return None
        return (time.monotonic() if now is None else now) - sample.received

    def is_stale(self, key: str, now: float | None = None) -> bool:
        """No value yet, or older than the staleness timeout (an interval of 0 = disabled)."""
        if self._intervals_ms.get(key) == 0:
            return False
        age = self.age(key, now)
        return age is None or age > self.stale_timeout_for(key)

    def node_silent(self, node_id: int | None = None, now: float | None = None) -> bool:
        node = self.config.turret_node_id if node_id is None else node_id
        seen = self._node_seen.get(node)
        now = time.monotonic() if now is None else now
        return seen is None or now - seen > self.config.node_timeout

    def node_last_seen(self, node_id: int) -> float | None:
        return self._node_seen.get(node_id)

    def _seen(self, node_id: int, now: float) -> None:
        self._node_seen[node_id] = now
        self._frames_at_seen[node_id] = self.counters.frames

    def frames_since_seen(self, node_id: int) -> int:
        """CAN frames received since ``node_id`` last spoke (all of them if it never did):
        a silent node on a bus that still carries frames is not a silent bus."""
        return self.counters.frames - self._frames_at_seen.get(node_id, 0)

    # --- sending ------------------------------------------------------------------

    def send(self, message: CanAerospaceMessage) -> None:
        """Send one message; LinkError when the interface is closed or the send fails."""
        bus = self._bus
        if bus is None:
            raise LinkError(f"CAN interface {self.description} is not open"
                            + (f" ({self.last_link_error})" if self.last_link_error else ""))
        frame = can.Message(arbitration_id=message.can_id, is_extended_id=False,
                            data=message.to_bytes(pad=self.config.pad_frames))
        try:
            with self._send_lock:
                bus.send(frame, timeout=0.2)
        except (can.CanError, OSError, ValueError) as exc:
            self._drop_bus(f"send failed: {exc}")
            raise LinkError(f"sending on {self.description} failed: {exc}") from exc

    def command(self, key: str, value: object) -> None:
        """Send a command identifier (by key) with the master node-id and a rolling code."""
        ident = BY_KEY.get(key)
        if ident is None or ident.direction is not Direction.COMMAND:
            raise CommandError(f"{key!r} is not a command identifier of this driver")
        try:
            message = CanAerospaceMessage.build(
                ident.can_id, self.config.client_node_id, ident.data_type, value, 0,
                self._codes.next(ident.can_id))
        except CodecError as exc:
            raise CommandError(f"{ident.name}: {exc}") from exc
        self.send(message)

    @staticmethod
    def _axis(axis: str) -> str:
        if axis not in AXES:
            raise CommandError(f"unknown axis {axis!r}; the turret has {', '.join(AXES)}")
        return axis

    @staticmethod
    def _finite(what: str, value: float) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or not math.isfinite(value):
            raise CommandError(f"{what} must be a finite number, got {value!r}")
        return float(value)

    def move_to(self, axis: str, position_rad: float) -> None:
        """Absolute position set-point (rad); the ICD range is -180..180 deg."""
        axis = self._axis(axis)
        degrees = math.degrees(self._finite(f"{axis} position", position_rad))
        if abs(degrees) > ICD_POSITION_LIMIT_DEG + 1e-9:
            raise CommandError(f"{axis} position {position_rad:.4f} rad is outside the "
                               f"device range -pi..pi")
        self.command(f"{axis}_position_setpoint", max(-180.0, min(180.0, degrees)))

    def jog(self, axis: str, velocity_rad_s: float) -> None:
        axis = self._axis(axis)
        degrees = math.degrees(self._finite(f"{axis} velocity", velocity_rad_s))
        self.command(f"{axis}_velocity_setpoint", degrees)

    def move_by(self, axis: str, offset_rad: float) -> None:
        axis = self._axis(axis)
        degrees = math.degrees(self._finite(f"{axis} offset", offset_rad))
        self.command(f"{axis}_relative_setpoint", degrees)

    def stop(self, axes: tuple[str, ...] | list[str] = AXES) -> None:
        bits = 0
        for axis in axes:
            bits |= STOP_YAW_BIT if self._axis(axis) == "yaw" else STOP_PITCH_BIT
        if bits:
            self.command("stop_actuators", bits)

    def set_actuator_mode(self, axis: str, mode: int | ActuatorMode) -> None:
        axis = self._axis(axis)
        try:
            mode = ActuatorMode(mode)
        except ValueError as exc:
            names = ", ".join(f"{m.value}={m.name.lower()}" for m in ActuatorMode)
            raise CommandError(f"actuator mode {mode!r} does not exist ({names})") from exc
        self.command(f"{axis}_actuator_mode", int(mode))

    def remember_position(self) -> None:
        self.command("remember_position", 1)

    def restore_position(self) -> None:
        self.command("restore_position", 1)

    def set_cover(self, open_cover: bool) -> None:
        self.command("cover_control", 1 if open_cover else 0)

    def set_fan(self, on: bool) -> None:
        self.command("fan_control", 1 if on else 0)

    def set_oes_heater(self, on: bool) -> None:
        self.command("oes_heater_control", 1 if on else 0)

    def set_drives_heater(self, on: bool) -> None:
        self.command("drives_heater_control", 1 if on else 0)

    def set_charging(self, on: bool) -> None:
        self.command("charging_control", 1 if on else 0)

    # --- node services --------------------------------------------------------------

    def request(self, message: CanAerospaceMessage) -> CanAerospaceMessage:
        """Send a node-service request and wait for its response (ICD: within 100 ms)."""
        service = ns.ServiceCode(message.service_code).name
        attempts = max(1, self.config.service_attempts)
        with self._service_lock:
            for _ in range(attempts):
                with self._exchange_for(message) as exchange:
                    self.send(message)
                    response = exchange.wait_next(self.config.service_timeout)
                if response is not None:
                    return response
                if self._bus is None:
                    raise LinkError(f"CAN interface {self.description} lost during {service}"
                                    f": {self.last_link_error}")
        raise ServiceTimeout(
            f"no {service} response from node {message.node_id} within "
            f"{self.config.service_timeout * 1000:.0f} ms ({attempts} attempts) on "
            f"{self.description}")

    @contextlib.contextmanager
    def _exchange_for(self, request: CanAerospaceMessage) -> Iterator[_Exchange]:
        exchange = _Exchange(request)
        self._exchange = exchange
        try:
            yield exchange
        finally:
            self._exchange = None

    def download(self, memory_id: int, data: bytes, node_id: int | None = None) -> int:
        """DDS: write a 1..1020 byte block to node memory; returns the verified checksum.

        Follows the node's XON/XOFF flow control; ABORT/INVALID or a checksum that does not
        match the bytes sent raise ServiceError.
        """
        node = self.config.turret_node_id if node_id is None else node_id
        first = self.config.transfer_first_number
        try:
            request_id, _ = ns.service_channel_ids(self.config.service_channel)
            messages = ns.transfer_messages(request_id, node, ns.ServiceCode.DDS, bytes(data),
                                            first)
            start = ns.start_transfer_request(node, ns.ServiceCode.DDS, memory_id,
                                              len(messages), self.config.service_channel)
        except CodecError as exc:
            raise CommandError(f"DDS: {exc}") from exc
        timeout = self.config.service_timeout
        with self._service_lock, self._exchange_for(start) as exchange:
            flow = ns.response_status(self._start_transfer(exchange, start, "DDS", node))
            final = None
            for message in messages:
                while flow != ns.ServiceStatus.XON:
                    if flow in (ns.ServiceStatus.ABORT, ns.ServiceStatus.INVALID):
                        raise ServiceRefused(self._download_ended(node, flow))
                    reply = exchange.wait_next(timeout * 10)  # XOFF: wait for XON
                    if reply is None:
                        raise ServiceTimeout(f"node {node} paused the download (XOFF) and "
                                           "never resumed")
                    flow = ns.response_status(reply)
                self.send(message)
                for pending in exchange.drain():
                    if pending.data_type == DataType.CHKSUM:
                        final = pending
                    else:
                        flow = self._download_reply(pending, node)
            deadline = time.monotonic() + timeout * 5
            while final is None:
                reply = exchange.wait_next(max(0.0, deadline - time.monotonic()))
                if reply is None:
                    raise ServiceTimeout(f"node {node} sent no DDS checksum")
                if reply.data_type == DataType.CHKSUM:
                    final = reply
                else:
                    self._download_reply(reply, node)
            reply = final
        expected = ns.block_checksum(bytes(data))
        if reply.value != expected:
            raise ServiceError(f"DDS checksum mismatch: node {node} reports {reply.value}, "
                               f"sent bytes sum to {expected}")
        last = messages[-1].message_code
        if reply.message_code != last:
            raise ServiceError(f"DDS checksum response of node {node} carries message "
                               f"number {reply.message_code}, the last data message was "
                               f"{last}: {self._numbering_hint()}")
        return expected

    def _start_transfer(self, exchange: _Exchange, start: CanAerospaceMessage, service: str,
                        node: int) -> CanAerospaceMessage:
        """Send a DDS/DUS start request (no retry: a repeated start would restart the
        transfer) and return the node's first response."""
        self.send(start)
        timeout = self.config.service_timeout
        reply = exchange.wait_next(timeout)
        if reply is None:
            raise ServiceTimeout(f"no {service} response from node {node} within "
                                 f"{timeout * 1000:.0f} ms")
        return reply

    def _numbering_hint(self) -> str:
        first = self.config.transfer_first_number
        return (f"this client counts DDS/DUS data messages from {first}; the node may count "
                f"from {1 - first} (transfer_first_number)")

    def _download_ended(self, node: int, status: int) -> str:
        text = (f"node {node} ended the download: "
                f"{ns.status_text(ns.ServiceCode.DDS, status)}")
        if status == ns.ServiceStatus.ABORT:
            text += f" (a node aborts on an unexpected message number; {self._numbering_hint()})"
        return text

    def _download_reply(self, reply: CanAerospaceMessage, node: int) -> int:
        status = ns.response_status(reply)
        if status in (ns.ServiceStatus.ABORT, ns.ServiceStatus.INVALID):
            raise ServiceRefused(self._download_ended(node, status))
        return status

    def upload(self, memory_id: int, length: int, node_id: int | None = None) -> bytes:
        """DUS: read `length` (1..1020) bytes of node memory, checking numbers and checksum."""
        node = self.config.turret_node_id if node_id is None else node_id
        if not 1 <= length <= ns.MAX_BLOCK_BYTES:
            raise CommandError(f"DUS: length {length} is outside 1..{ns.MAX_BLOCK_BYTES}")
        count = (length + 3) // 4
        try:
            start = ns.start_transfer_request(node, ns.ServiceCode.DUS, memory_id, count,
                                              self.config.service_channel)
        except CodecError as exc:
            raise CommandError(f"DUS: {exc}") from exc
        timeout = self.config.service_timeout
        received: dict[int, bytes] = {}
        with self._service_lock, self._exchange_for(start) as exchange:
            status = ns.response_status(self._start_transfer(exchange, start, "DUS", node))
            if status != ns.ServiceStatus.OK:
                raise ServiceRefused(f"node {node} refused the upload of memory {memory_id}: "
                                   f"{ns.status_text(ns.ServiceCode.DUS, status)}")
            deadline = time.monotonic() + timeout + 0.01 * count + 0.5
            while True:
                reply = exchange.wait_next(max(0.0, deadline - time.monotonic()))
                if reply is None:
                    raise ServiceTimeout(f"DUS from node {node}: {len(received)} of {count} "
                                       "data messages, then silence")
                if reply.data_type == DataType.CHKSUM:
                    break
                if reply.data_type == DataType.LONG:
                    raise ServiceRefused(f"node {node} aborted the upload: "
                                       f"{ns.status_text(ns.ServiceCode.DUS, int(reply.value))}")
                value = reply.value
                received[reply.message_code] = bytes(value if isinstance(value, tuple)
                                                     else (value,))
        numbers = ns.data_numbers(count, self.config.transfer_first_number)
        missing = [n for n in numbers if n not in received]
        if missing:
            raise ServiceError(f"DUS from node {node}: data messages {missing} missing "
                               f"(received {sorted(received)}; {self._numbering_hint()})")
        if reply.message_code != numbers[-1]:
            raise ServiceError(f"DUS checksum response of node {node} carries message "
                               f"number {reply.message_code}, expected {numbers[-1]}: "
                               f"{self._numbering_hint()}")
        data = b"".join(received[n] for n in numbers)
        if reply.value != ns.block_checksum(data):
            raise ServiceError(f"DUS checksum mismatch: node {node} reports {reply.value}, "
                               f"received bytes sum to {ns.block_checksum(data)}")
        return data[:length]

    def identify(self, node_id: int | None = None) -> ns.IdentificationInfo:
        node = self.config.turret_node_id if node_id is None else node_id
        response = self.request(ns.ids_request(node, self.config.service_channel))
        try:
            return ns.parse_ids_response(response)
        except CodecError as exc:
            raise ServiceError(f"IDS response from node {node} is malformed: {exc}") from exc

    def set_transmission_interval(self, key: str, interval_ms: int) -> None:
        """TIS for one data identifier (0 stops it; the node decides the valid range)."""
        ident = self._data_ident(key)
        node = self._expected_node(ident)
        try:
            request = ns.tis_request(node, ident.can_id, int(interval_ms),
                                     self.config.service_channel)
        except CodecError as exc:
            raise CommandError(f"TIS for {key}: {exc}") from exc
        status = ns.response_status(self.request(request))
        if status != ns.ServiceStatus.OK:
            raise ServiceRefused(f"node {node} refused TIS {key} (id {ident.can_id}) = "
                               f"{interval_ms} ms: {ns.status_text(ns.ServiceCode.TIS, status)}")
        self._intervals_ms[key] = int(interval_ms)
        self._observed_interval.pop(key, None)

    def request_intervals(self, intervals: dict[str, int]) -> dict[str, str]:
        """TIS for several identifiers; returns {key: reason} for those that were refused.

        A refusal (negative status or no answer) is not an error: the identifier keeps the
        rate the node chose, which staleness and rate checks then learn from the frames
        (`interval_of`). A closed interface still raises LinkError.
        """
        refused: dict[str, str] = {}
        for key, interval_ms in intervals.items():
            try:
                self.set_transmission_interval(key, interval_ms)
            except ServiceError as exc:
                if self._bus is None:
                    raise LinkError(str(exc)) from exc
                refused[key] = str(exc)
                self._intervals_ms.pop(key, None)
        self.refused_intervals = refused
        return refused

    def interval_of(self, key: str) -> float | None:
        """Seconds between two frames of `key`: the accepted TIS interval, else as observed."""
        interval_ms = self._intervals_ms.get(key)
        if interval_ms:
            return interval_ms / 1000.0
        return self._observed_interval.get(key)

    def accepted_interval_ms(self, key: str) -> int | None:
        """The interval (ms) a node accepted by TIS for `key`, None when never set."""
        return self._intervals_ms.get(key)

    def _data_ident(self, key: str) -> Identifier:
        for ident in self._table.values():
            if ident.key == key and ident.direction is Direction.DATA:
                return ident
        raise CommandError(f"{key!r} is not a data identifier of this driver")

    def set_node_id(self, new_node_id: int, node_id: int | None = None) -> None:
        """NIS: only when `allow_node_id_change` is set (changes the device's identity)."""
        if not self.config.allow_node_id_change:
            raise NotAllowedError("node-id changes (NIS) are disabled; enable "
                                  "allow_node_id_change to use them")
        node = self.config.turret_node_id if node_id is None else node_id
        try:
            request = ns.nis_request(node, new_node_id, self.config.service_channel)
        except CodecError as exc:
            raise CommandError(str(exc)) from exc
        status = ns.response_status(self.request(request))
        if status != ns.ServiceStatus.OK:
            raise ServiceRefused(f"node {node} refused node-id {new_node_id}: "
                               f"{ns.status_text(ns.ServiceCode.NIS, status)}")
        for name in ("turret_node_id", "cover_node_id", "rover_gnss_node_id",
                     "base_gnss_node_id", "zoom_node_id"):
            if getattr(self.config, name) == node:
                setattr(self.config, name, new_node_id)

    def store_configuration(self, security_code: int, node_id: int | None = None) -> None:
        """FPS: write the node's configuration to flash; only with allow_flash_programming."""
        if not self.config.allow_flash_programming:
            raise NotAllowedError("flash programming (FPS) is disabled; enable "
                                  "allow_flash_programming to use it")
        node = self.config.turret_node_id if node_id is None else node_id
        if not 0 <= security_code <= 255:
            raise CommandError(f"FPS security code {security_code} is outside 0..255")
        status = ns.response_status(self.request(
            ns.fps_request(node, security_code, self.config.service_channel)))
        if status != ns.ServiceStatus.OK:
            raise ServiceRefused(f"node {node} refused flash programming: "
                               f"{ns.status_text(ns.ServiceCode.FPS, status)}")

    def data_identifiers(self) -> list[Identifier]:
        """The data identifiers this client decodes (with the configured zoom id)."""
        return [i for i in self._table.values() if i.direction is Direction.DATA]

    def data_type_of(self, key: str) -> DataType:
        return self._data_ident(key).data_type
