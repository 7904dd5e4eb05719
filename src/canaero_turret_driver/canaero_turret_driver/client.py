"""Turret session on a python-can bus: value cache, commands, node services (no ROS).

The client owns one `can.BusABC` (any python-can interface: socketcan on a robot, slcan or
virtual here) as the link of a :class:`gimbal_driver_common.session.Session` (reader
thread ``canaero-reader``) whose protocol the client is: each frame is decoded, the latest
value of each data identifier kept with its arrival time, message-code sequences tracked
per identifier, EED events collected, and node-service responses handed to the pending
request of its part :attr:`TurretClient.services` (``client_services.py``
:class:`~.client_services.NodeServices`, handed the client's side of the bus and the
transmission :attr:`TurretClient.intervals`). Interface errors (bus-off error frames, a vanished
adapter, a failing send) end the session; `connected` turns False and whoever supervises
the link (the controller of gimbal_driver_common, through `TurretDevice`) closes and
reopens it.

Units: the client speaks the ICD's own units both ways: a sample carries the value as the
bus carried it (degrees, degrees/s, ...), and commands take degrees. The adapter alone
converts (`readings.si` for what arrives; `TurretDevice` SI and REP-103 directions, and
the set-point range, for commands).
Errors are the core's hierarchy (`gimbal_driver_common.errors`).

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

import can

from gimbal_driver_common import errors
from gimbal_driver_common.session import Pending, Protocol, Session

from .can_link import CanLink, Garbled
from .client_services import Intervals, NodeServices
from .client_types import (
    ClientConfig,
    CommandError,
    Counters,
    LinkError,
    NotAllowedError,
    Sample,
    ServiceError,
    ServiceRefused,
    ServiceTimeout,
    TurretError,
)
from .protocol import nodeservice as ns
from .protocol.datatypes import DataType
from .protocol.eed import EmergencyEvent, decode_eed, is_eed
from .protocol.errors import CodecError
from .protocol.identifiers import (
    BASE_GNSS_NODE_ID,
    BY_KEY,
    COVER_NODE_ID,
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

__all__ = ["AXES", "ClientConfig", "CommandError", "Counters", "LinkError", "NotAllowedError",
           "Sample", "ServiceError", "ServiceRefused", "ServiceTimeout", "TurretClient",
           "TurretError"]


def _default_bus_factory(config: ClientConfig) -> can.BusABC:
    """python-can's bus for the configured interface (slcan: the chunked reader).

    A TCP bridge (socketcand, slcan over ``socket://``) whose far end leaves Nagle's
    algorithm on is not a rate trap here, so the socket python-can owns is left as it
    is: the joint states are the turret's own periodic broadcasts, which the receive
    thread takes as they come (a bridge that bunches them behind a delayed ACK delivers
    every one, later), and the poll waits for no batch of replies. At worst a
    multi-frame node-service answer arrives up to a delayed-ACK time later, inside its
    service timeout."""
    kwargs = dict(config.bus_options)
    if config.bitrate:
        kwargs["bitrate"] = config.bitrate
    return open_bus(config.interface, config.channel, **kwargs)


class TurretClient(Protocol):
    """A CANaerospace master talking to the turret and its companion nodes."""

    def __init__(self, config: ClientConfig | None = None,
                 bus_factory: Callable[[ClientConfig], can.BusABC] | None = None) -> None:
        self.config = config or ClientConfig()
        self._bus_factory = bus_factory or _default_bus_factory
        self._table = identifier_table(self.config.zoom_position_id)
        self._session: Session | None = None
        self._cache_lock = threading.Lock()
        self._cache: dict[str, Sample] = {}
        self._node_seen: dict[int, float] = {}
        self._frames_at_seen: dict[int, int] = {}  # counters.frames when the node last spoke
        #: TIS intervals accepted or refused, and as observed on the bus
        self.intervals = Intervals()
        #: IDS, TIS, NIS, FPS, DDS, DUS (a part handed this client and the intervals)
        self.services = NodeServices(self, self.intervals)
        self._codes = MessageCodeCounter()
        #: message-code bookkeeping per (node-id, CAN id)
        self.sequences: MessageCodeTracker[tuple[int, int]] = MessageCodeTracker()
        self.counters = Counters()
        self.events: deque[EmergencyEvent] = deque(maxlen=50)
        self._link_error = ""
        self._garbled_in_row = 0
        self._last_frame = time.monotonic()
        #: when the reader last came back from the bus (a frame or a read that timed out)
        self._listened_at = self._last_frame
        self._opened_before = False
        self.on_sample: Callable[[Sample], None] | None = None
        self.on_sequence: Callable[[str, SequenceEvent, int], None] | None = None
        self.on_link: Callable[[bool, str], None] | None = None

    # --- link ---------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        session = self._session
        return session is not None and session.alive

    @property
    def last_link_error(self) -> str:
        """Why the interface is not open ("" while it is, or before it ever was)."""
        session = self._session
        if session is not None and session.error is not None:
            return str(session.error)
        return self._link_error

    @property
    def description(self) -> str:
        return f"{self.config.interface}:{self.config.channel}"

    def open(self) -> None:
        """Open the CAN interface (raises LinkError) and start its session's reader.

        After the link dropped, call `close()` and then `open()` again: the client has no
        reconnect loop of its own (the controller's supervisor is the only one).
        """
        if self.connected:
            return
        self.close()
        try:
            bus = self._bus_factory(self.config)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            self._link_error = f"cannot open CAN interface {self.description}: {exc}"
            raise LinkError(self._link_error) from exc
        if self._opened_before:
            self.counters.reconnects += 1
        self._opened_before = True
        self._last_frame = self._listened_at = time.monotonic()
        self._garbled_in_row = 0
        self.sequences.reset()
        self._link_error = ""
        session = Session(CanLink(bus, self.description), self, "canaero", link_error=LinkError)
        self._session = session
        LOG.info("CAN interface %s open", self.description)
        if self.on_link is not None:  # before the reader runs: a loss is reported after it
            self.on_link(True, f"CAN interface {self.description} open")
        session.start()

    def close(self) -> None:
        """End the session: stop its reader, release the interface. Safe to call twice."""
        session, self._session = self._session, None
        if session is not None:
            session.close()

    # --- session protocol (on the reader thread) -------------------------------------

    def data_received(self, frame: can.Message | Garbled) -> None:
        if isinstance(frame, Garbled):
            self._garbled(frame.error)
            return
        self._last_frame = time.monotonic()
        self._garbled_in_row = 0
        self._dispatch(frame)

    def tick(self, now: float) -> float | None:
        """A transport that went quiet instead of failing (reopen_after_silence)."""
        self._listened_at = now
        quiet = now - self._last_frame
        if 0 < self.config.reopen_after_silence < quiet:
            raise LinkError(f"no CAN frame for {quiet:.1f} s: the interface looks dead")
        return None

    def connection_lost(self, error: errors.LinkError | None) -> None:
        """`on_link(False, reason)` either way (the session already warned of a loss)."""
        reason = "closed" if error is None else str(error)
        self._link_error = reason
        if self.on_link is not None:
            self.on_link(False, reason)

    # --- receive ------------------------------------------------------------------

    def _garbled(self, exc: BaseException) -> None:
        """A record the adapter could not parse (the link flushed it); the interface is
        given up when records keep failing."""
        self._malformed(f"garbled record from the adapter: {exc}")
        self._garbled_in_row += 1
        if self._garbled_in_row >= 20:
            self._garbled_in_row = 0
            self._lose("the adapter keeps sending unreadable records")

    def _lose(self, reason: str) -> None:
        """Give the interface up (the session reports it once and ends)."""
        session = self._session
        if session is not None:
            session.lose(LinkError(reason))

    def _malformed(self, text: str) -> None:
        self.counters.malformed += 1
        self.counters.last_malformed = text
        LOG.debug("malformed: %s", text)

    def expected_node(self, ident: Identifier) -> int:
        """The node-id that sends ``ident`` (the configured one)."""
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
                self._lose("bus-off reported by the CAN controller")
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
        if ns.service_channel_of(message.can_id) is not None:
            session = self._session
            if session is not None:
                session.dispatch(message)  # to the pending node-service request
            return
        ident = self._table.get(message.can_id)
        if ident is None or ident.direction is not Direction.DATA:
            self.counters.unknown += 1
            return
        if message.node_id != self.expected_node(ident):
            self.counters.foreign_node += 1
            return
        self._seen(message.node_id, now)
        if message.data_type != ident.data_type:
            self.counters.type_mismatch += 1
            self._malformed(f"id {message.can_id} ({ident.key}) carries {message.type_name}, "
                            f"the ICD says {ident.data_type.name}")
            return
        order, missed = self.sequences.update((message.node_id, message.can_id),
                                              message.message_code)
        if order not in (SequenceEvent.FIRST, SequenceEvent.IN_ORDER) \
                and self.on_sequence is not None:
            self.on_sequence(ident.key, order, missed)
        if not order.accepted:
            return  # an old or duplicate value must not replace the newer one
        value = message.value
        sample = Sample(ident.key, value, time.time(), now, message.message_code,
                        message.node_id)
        with self._cache_lock:
            previous = self._cache.get(ident.key)
            self._cache[ident.key] = sample
        if previous is not None:
            self.intervals.learn(ident.key, now - previous.received)
        if self.on_sample is not None:
            self.on_sample(sample)

    @contextlib.contextmanager
    def expect(self, request: CanAerospaceMessage) -> Iterator[Pending]:
        """The session's pending request for the node's responses to ``request``."""
        session = self._session
        if session is None:
            raise LinkError(f"CAN interface {self.description} is not open")

        def answers(message: object) -> bool:
            if isinstance(message, CanAerospaceMessage) and ns.is_response_to(request, message):
                self._seen(message.node_id, time.monotonic())
                return True
            return False

        with session.expect(answers) as pending:
            yield pending

    # --- cache --------------------------------------------------------------------

    def latest(self, key: str) -> Sample | None:
        with self._cache_lock:
            return self._cache.get(key)

    def snapshot(self) -> dict[str, Sample]:
        with self._cache_lock:
            return dict(self._cache)

    def stale_timeout_for(self, key: str) -> float:
        """`stale_timeout`, or 3 transmission intervals for slower identifiers.

        The interval is the one the node accepted by TIS; without one (never requested,
        or refused) it is the interval observed on the bus.
        """
        interval = self.intervals.interval_of(key)
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
        if self.intervals.disabled(key):
            return False
        age = self.age(key, now)
        return age is None or age > self.stale_timeout_for(key)

    def node_silent(self, node_id: int | None = None, now: float | None = None) -> bool:
        """Whether ``node_id`` (the turret node by default) said nothing for node_timeout
        while this client listened."""
        silent_for = self.silent_for(node_id, now)
        return silent_for is None or silent_for > self.config.node_timeout

    def silent_for(self, node_id: int | None = None, now: float | None = None) -> float | None:
        """Seconds the reader listened without hearing ``node_id`` (None: never heard).

        Counted up to the reader's last look at the bus, not up to now: a reader that stood
        still heard nothing, and that says nothing of the node. It stands still when this
        process stalls or while it waits behind the device thread (both take samples under
        one lock, ``StreamedSamples``), and reads the frames that came meanwhile first when
        it runs again. Judged up to now, a 5 s stall of the node's device thread on a loaded
        core read as "turret node 1 silent for 5.7 s (no CAN frames ...)" and dropped a link
        the turret had kept talking on. With no session nothing listens: up to now.
        """
        node = self.config.turret_node_id if node_id is None else node_id
        seen = self._node_seen.get(node)
        if seen is None:
            return None
        now = time.monotonic() if now is None else now
        heard_until = min(now, max(self._listened_at, self._last_frame)) if self.connected \
            else now
        return heard_until - seen

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
        session = self._session
        if session is None or not session.alive:
            reason = self.last_link_error
            raise LinkError(f"CAN interface {self.description} is not open"
                            + (f" ({reason})" if reason else ""))
        frame = can.Message(arbitration_id=message.can_id, is_extended_id=False,
                            data=message.to_bytes(pad=self.config.pad_frames))
        try:
            session.write(frame)
        except errors.LinkError as exc:
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

    def move_to(self, axis: str, position_deg: float) -> None:
        """Absolute position set-point in the ICD's degrees (the adapter checks the range)."""
        axis = self._axis(axis)
        self.command(f"{axis}_position_setpoint", self._finite(f"{axis} position",
                                                               position_deg))

    def jog(self, axis: str, velocity_deg_s: float) -> None:
        """Velocity set-point in degrees/s."""
        axis = self._axis(axis)
        self.command(f"{axis}_velocity_setpoint", self._finite(f"{axis} velocity",
                                                               velocity_deg_s))

    def move_by(self, axis: str, offset_deg: float) -> None:
        """Relative set-point in degrees."""
        axis = self._axis(axis)
        self.command(f"{axis}_relative_setpoint", self._finite(f"{axis} offset", offset_deg))

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

    def data_identifiers(self) -> list[Identifier]:
        """The data identifiers this client decodes (with the configured zoom id)."""
        return [i for i in self._table.values() if i.direction is Direction.DATA]

    def data_identifier(self, key: str) -> Identifier:
        """The data identifier ``key`` names (CommandError for any other)."""
        for ident in self._table.values():
            if ident.key == key and ident.direction is Direction.DATA:
                return ident
        raise CommandError(f"{key!r} is not a data identifier of this driver")

    def data_type_of(self, key: str) -> DataType:
        return self.data_identifier(key).data_type
