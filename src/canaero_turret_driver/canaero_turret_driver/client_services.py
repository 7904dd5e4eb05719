"""CANaerospace node services of the turret client: IDS, TIS, NIS, FPS and the DDS/DUS
memory transfers (no ROS).

A part of :class:`~.client.TurretClient` (its ``services`` attribute), handed the client's
side of the bus (:class:`ServiceLink`: ``send``, ``expect``, a pending request that collects
the node's responses in order, the configuration and the identifier lookups) and the
transmission intervals (:class:`Intervals`, which the client's receive path learns from and
its staleness checks read). One service exchange at a time (its own lock).
"""

from __future__ import annotations

import threading
import time
from contextlib import AbstractContextManager
from typing import Protocol

from gimbal_driver_common import errors
from gimbal_driver_common.session import Pending

from .client_types import (
    ClientConfig,
    CommandError,
    LinkError,
    NotAllowedError,
    ServiceError,
    ServiceRefused,
    ServiceTimeout,
)
from .protocol import nodeservice as ns
from .protocol.datatypes import DataType
from .protocol.errors import CodecError
from .protocol.identifiers import Identifier
from .protocol.message import CanAerospaceMessage


class ServiceLink(Protocol):
    """What the node services use of the client (:class:`~.client.TurretClient`)."""

    config: ClientConfig

    @property
    def connected(self) -> bool:
        """The interface is open."""

    @property
    def description(self) -> str:
        """The interface, for messages."""

    @property
    def last_link_error(self) -> str:
        """Why the interface is not open."""

    def send(self, message: CanAerospaceMessage) -> None:
        """Send one message (LinkError when the interface is closed)."""

    def expect(self, request: CanAerospaceMessage) -> AbstractContextManager[Pending]:
        """The session's pending request for the node's responses to ``request``."""

    def data_identifier(self, key: str) -> Identifier:
        """The data identifier ``key`` names (CommandError for any other)."""

    def expected_node(self, ident: Identifier) -> int:
        """The node-id that sends ``ident`` (the configured one)."""


class Intervals:
    """How often each data identifier arrives: the TIS interval a node accepted, the
    refusals, and the interval observed on the bus (the ICD leaves intervals to the
    device). The services write the first two, the client's receive path the third."""

    def __init__(self) -> None:
        self.accepted_ms: dict[str, int] = {}   # TIS intervals the nodes accepted
        self.refused: dict[str, str] = {}       # key -> why TIS was refused (a status)
        self.timed_out: dict[str, str] = {}     # key -> the TIS that got no answer in time
        self.observed: dict[str, float] = {}

    def failures(self) -> str:
        """What became of the TIS requests that failed, for the log and diagnostics:
        refused (the node answered with a status) and timed out (no answer) said apart;
        '' when none failed."""
        parts = []
        if self.refused:
            parts.append(f"the turret refused TIS for {', '.join(sorted(self.refused))}")
        if self.timed_out:
            parts.append(f"TIS for {', '.join(sorted(self.timed_out))} timed out "
                         "(no answer)")
        return '; '.join(parts)

    def learn(self, key: str, gap: float) -> None:
        """A smoothed inter-arrival time; gaps longer than 4x the estimate (an outage, a
        silence) do not inflate it."""
        estimate = self.observed.get(key)
        if estimate is None:
            self.observed[key] = gap
        elif gap <= 4.0 * estimate:
            self.observed[key] = 0.8 * estimate + 0.2 * gap

    def interval_of(self, key: str) -> float | None:
        """Seconds between two frames of `key`: the accepted TIS interval, else as observed."""
        interval_ms = self.accepted_ms.get(key)
        if interval_ms:
            return interval_ms / 1000.0
        return self.observed.get(key)

    def accepted_interval_ms(self, key: str) -> int | None:
        """The interval (ms) a node accepted by TIS for `key`, None when never set."""
        return self.accepted_ms.get(key)

    def disabled(self, key: str) -> bool:
        """A node accepted interval 0 for `key`: it is not sent at all."""
        return self.accepted_ms.get(key) == 0


class NodeServices:
    """Node-service requests on the client's service channel."""

    def __init__(self, link: ServiceLink, intervals: Intervals) -> None:
        self._link = link
        self.intervals = intervals
        self._service_lock = threading.Lock()

    @property
    def config(self) -> ClientConfig:
        return self._link.config

    def send(self, message: CanAerospaceMessage) -> None:
        self._link.send(message)

    def _expect(self, request: CanAerospaceMessage) -> AbstractContextManager[Pending]:
        return self._link.expect(request)

    def request(self, message: CanAerospaceMessage) -> CanAerospaceMessage:
        """Send a node-service request and wait for its response (ICD: within 100 ms)."""
        service = ns.ServiceCode(message.service_code).name
        attempts = max(1, self.config.service_attempts)
        with self._service_lock:
            for _ in range(attempts):
                with self._expect(message) as exchange:
                    self.send(message)
                    response = self._next(exchange, self.config.service_timeout)
                if response is not None:
                    return response
                if not self._link.connected:
                    raise LinkError(f"CAN interface {self._link.description} lost during "
                                    f"{service}: {self._link.last_link_error}")
        raise ServiceTimeout(
            f"no {service} response from node {message.node_id} within "
            f"{self.config.service_timeout * 1000:.0f} ms ({attempts} attempts) on "
            f"{self._link.description}")

    @staticmethod
    def _next(pending: Pending, timeout: float) -> CanAerospaceMessage | None:
        """The node's next response, None when none came in time or the link went."""
        try:
            return pending.next(timeout)
        except (errors.DeviceTimeout, errors.LinkError):
            return None

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
        with self._service_lock, self._expect(start) as exchange:
            flow = ns.response_status(self._start_transfer(exchange, start, "DDS", node))
            final = None
            for message in messages:
                while flow != ns.ServiceStatus.XON:
                    if flow in (ns.ServiceStatus.ABORT, ns.ServiceStatus.INVALID):
                        raise ServiceRefused(self._download_ended(node, flow))
                    reply = self._next(exchange, timeout * 10)  # XOFF: wait for XON
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
                reply = self._next(exchange, max(0.0, deadline - time.monotonic()))
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

    def _start_transfer(self, exchange: Pending, start: CanAerospaceMessage, service: str,
                        node: int) -> CanAerospaceMessage:
        """Send a DDS/DUS start request (no retry: a repeated start would restart the
        transfer) and return the node's first response."""
        self.send(start)
        timeout = self.config.service_timeout
        reply = self._next(exchange, timeout)
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
        with self._service_lock, self._expect(start) as exchange:
            status = ns.response_status(self._start_transfer(exchange, start, "DUS", node))
            if status != ns.ServiceStatus.OK:
                raise ServiceRefused(f"node {node} refused the upload of memory {memory_id}: "
                                   f"{ns.status_text(ns.ServiceCode.DUS, status)}")
            deadline = time.monotonic() + timeout + 0.01 * count + 0.5
            while True:
                reply = self._next(exchange, max(0.0, deadline - time.monotonic()))
                if reply is None:
                    raise ServiceTimeout(f"DUS from node {node}: {len(received)} of {count} "
                                       "data messages, then silence")
                if reply.data_type == DataType.CHKSUM:
                    break
                value = reply.value
                if reply.data_type == DataType.LONG:
                    assert isinstance(value, int)  # the codec decodes a LONG to an int
                    raise ServiceRefused(f"node {node} aborted the upload: "
                                         f"{ns.status_text(ns.ServiceCode.DUS, value)}")
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
        ident = self._link.data_identifier(key)
        node = self._link.expected_node(ident)
        try:
            request = ns.tis_request(node, ident.can_id, int(interval_ms),
                                     self.config.service_channel)
        except CodecError as exc:
            raise CommandError(f"TIS for {key}: {exc}") from exc
        status = ns.response_status(self.request(request))
        if status != ns.ServiceStatus.OK:
            raise ServiceRefused(f"node {node} refused TIS {key} (id {ident.can_id}) = "
                               f"{interval_ms} ms: {ns.status_text(ns.ServiceCode.TIS, status)}")
        self.intervals.accepted_ms[key] = int(interval_ms)
        self.intervals.observed.pop(key, None)

    def request_intervals(self, intervals: dict[str, int]) -> dict[str, str]:
        """TIS for several identifiers; returns {key: reason} for those that failed:
        refused (a negative status, in ``intervals.refused``) or timed out (no answer, in
        ``intervals.timed_out``).

        Neither is an error: the identifier keeps the rate the node chose, which staleness
        and rate checks then learn from the frames (`interval_of`). A closed interface
        still raises LinkError.
        """
        refused: dict[str, str] = {}
        timed_out: dict[str, str] = {}
        for key, interval_ms in intervals.items():
            try:
                self.set_transmission_interval(key, interval_ms)
            except ServiceError as exc:
                if not self._link.connected:
                    raise LinkError(str(exc)) from exc
                (timed_out if isinstance(exc, ServiceTimeout) else refused)[key] = str(exc)
                self.intervals.accepted_ms.pop(key, None)
        self.intervals.refused, self.intervals.timed_out = refused, timed_out
        return {**refused, **timed_out}

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
