"""gimbal_probe's core: which registered device answers on a link, and how (no ROS).

Each driver registers a probe function (``DriverSpec.probe``, a ``'module:function'``
reference). Given a :class:`ProbeLink` it returns the :class:`Attempt` s it would make on that
link (none when the link is not its kind): one per baud rate, TCP port or node id to try,
each sending only what the device documents as a read or as its session handshake. This
module runs the attempts one at a time, each with a time limit, stops trying a port once a
device answered there, and reports what answered (:class:`Found`) or what was tried.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

from gimbal_driver_common.errors import GimbalError
from gimbal_driver_common.registry import DriverSpec, RegistryError, drivers, resolve
from gimbal_driver_common.transport import ByteStream, TransportError

LINK_KINDS = ('serial', 'tcp', 'can')
#: seconds an attempt may overrun its own timeout (closing a port, a thread's join)
GRACE_S = 1.5


@dataclass(frozen=True)
class ProbeLink:
    """Where to look: a serial port, a TCP host (port 0: each device's own), or a CAN bus."""

    kind: str
    serial_port: str = ''
    host: str = ''
    port: int = 0
    can_channel: str = ''
    can_interface: str = 'socketcan'
    can_bitrate: int = 0
    #: a device password (Kessler kOS); never printed, never written
    password: str = field(default='', repr=False)
    #: seconds one attempt may wait for its answers
    timeout: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in LINK_KINDS:
            raise ValueError(f'link kind {self.kind!r} is not one of {LINK_KINDS}')
        if self.timeout <= 0:
            raise ValueError(f'timeout must be > 0 s, not {self.timeout}')

    def describe(self) -> str:
        if self.kind == 'serial':
            return f'serial port {self.serial_port}'
        if self.kind == 'tcp':
            return f'TCP {self.host}:{self.port}' if self.port else \
                f'TCP {self.host} (each device\'s documented port)'
        bitrate = f' at {self.can_bitrate} bit/s' if self.can_bitrate else ''
        return f'CAN {self.can_interface} channel {self.can_channel}{bitrate}'


@dataclass
class Found:
    """A device that answered: what it is and the driver parameters that reach it."""

    device: str                              # e.g. 'Capture pan-tilt pedestal'
    protocol: str                            # e.g. 'Capture binary protocol over TCP'
    link: dict[str, Any]                     # link settings (baud rate, port, ...)
    identity: dict[str, str] = field(default_factory=dict)  # model, serial, firmware
    ids: dict[str, Any] = field(default_factory=dict)       # group, node ids, motors
    parameters: dict[str, Any] = field(default_factory=dict)  # the node's ros__parameters
    notes: list[str] = field(default_factory=list)          # e.g. 'a password is needed'
    driver: str = ''                         # filled in by the probe: the registry name
    node_name: str = ''                      # filled in: the node the YAML configures


class NoAnswer(GimbalError):
    """The attempt found no device of its kind; the message says what it saw."""


@dataclass
class Attempt:
    """One try: the settings it uses (for people) and the function that tries them."""

    settings: str
    endpoint: str                            # the port it uses: one found device claims it
    run: Callable[[], Found]
    #: False: settings the device does not document (a TCP port other than its own); the
    #: attempts of devices that document them go first
    documented: bool = True


@dataclass
class Outcome:
    driver: str
    settings: str
    found: Found | None = None
    reason: str = ''                         # why nothing was found


@dataclass
class Report:
    link: ProbeLink
    outcomes: list[Outcome] = field(default_factory=list)

    @property
    def found(self) -> list[Found]:
        return [o.found for o in self.outcomes if o.found is not None]


ProbeFunction = Callable[[ProbeLink], Iterable[Attempt]]


def registered_probes(specs: Iterable[DriverSpec] | None = None
                      ) -> list[tuple[DriverSpec, ProbeFunction]]:
    """Every registered driver that names a probe, with its probe function (one that
    does not load is reported when it is run, see :func:`run_probes`)."""
    found = []
    for spec in drivers() if specs is None else specs:
        if spec.probe:
            try:
                found.append((spec, resolve(spec.probe)))
            except RegistryError as exc:  # one broken driver: the others still probe
                found.append((spec, not_loaded(exc)))
    return found


def not_loaded(error: RegistryError) -> ProbeFunction:
    """A probe function that reports why the driver's probe did not load."""
    def probe(link: ProbeLink) -> list[Attempt]:
        raise error
    return probe


def run_probes(link: ProbeLink, probes: Iterable[tuple[DriverSpec, ProbeFunction]],
               on_outcome: Callable[[Outcome], None] | None = None) -> Report:
    """Run each driver's attempts on ``link``; an endpoint where a device answered is not
    tried again by the others (its device is known, and other protocols are noise to it)."""
    report = Report(link)

    def tell(outcome: Outcome) -> None:
        report.outcomes.append(outcome)
        if on_outcome is not None:
            on_outcome(outcome)

    planned: list[tuple[DriverSpec, Attempt]] = []
    for spec, function in probes:
        try:
            planned += [(spec, attempt) for attempt in function(link)]
        except (GimbalError, RegistryError, OSError, ValueError) as exc:
            tell(Outcome(spec.name, '-', reason=f'probe not run: {exc}'))
    planned.sort(key=lambda item: not item[1].documented)  # stable: registry order within
    claimed: set[str] = set()
    for spec, attempt in planned:
        if attempt.endpoint in claimed:
            continue
        outcome = run_attempt(spec, attempt, link.timeout + GRACE_S)
        if outcome.found is not None:
            claimed.add(attempt.endpoint)
        tell(outcome)
    return report


def run_attempt(spec: DriverSpec, attempt: Attempt, limit: float) -> Outcome:
    """Run one attempt in a thread of its own, for at most ``limit`` seconds; any error
    becomes the reason (a device that answers garbage is not a crash of the tool)."""
    outcome = Outcome(spec.name, attempt.settings)
    result: dict[str, Any] = {}

    def target() -> None:
        try:
            result['found'] = attempt.run()
        except NoAnswer as exc:
            result['reason'] = str(exc)
        except GimbalError as exc:
            result['reason'] = f'{type(exc).__name__}: {exc}'
        except Exception as exc:  # noqa: BLE001 - a reply no codec expected: say so, go on
            result['reason'] = f'unexpected answer ({type(exc).__name__}: {exc})'

    thread = threading.Thread(target=target, name=f'probe-{spec.name}', daemon=True)
    thread.start()
    thread.join(limit)
    if thread.is_alive():
        outcome.reason = f'no result within {limit:g} s (attempt abandoned)'
    elif 'found' in result:
        found: Found = result['found']
        found.driver, found.node_name = spec.name, spec.node_name
        outcome.found = found
    else:
        outcome.reason = result.get('reason', 'no answer')
    return outcome


class WatchedStream(ByteStream):
    """A :class:`ByteStream` that keeps the first bytes written and read, so a failed
    attempt can say what the line did: nothing, an echo of the request, or other bytes."""

    KEEP = 256

    def __init__(self, stream: ByteStream) -> None:
        self.stream = stream
        self.written = bytearray()
        self.received = bytearray()
        self.received_total = 0

    @property
    def description(self) -> str:
        return self.stream.description

    @property
    def is_open(self) -> bool:
        return self.stream.is_open

    def open(self) -> None:
        self.stream.open()

    def close(self) -> None:
        self.stream.close()

    def write(self, data: bytes) -> None:
        if len(self.written) < self.KEEP:
            self.written += data[:self.KEEP - len(self.written)]
        self.stream.write(data)

    def read(self, max_bytes: int, timeout: float) -> bytes:
        data = self.stream.read(max_bytes, timeout)
        self.received_total += len(data)
        if len(self.received) < self.KEEP:
            self.received += data[:self.KEEP - len(self.received)]
        return data


def line_verdict(watched: Iterable[WatchedStream], protocol: str, error: BaseException) -> str:
    """What the line did during a failed attempt, for people: silent, echoing, other bytes,
    or the link error itself."""
    streams = list(watched)
    written = b''.join(bytes(s.written) for s in streams)
    received = b''.join(bytes(s.received) for s in streams)
    total = sum(s.received_total for s in streams)
    if not received:
        if streams and link_failed(error):  # opened, then lost: not "cannot connect"
            return f'the link failed before any answer: {error}'
        if not written:
            return f'{error}'
        return f'silent: no byte came back ({error})'
    if written and (received.startswith(written[:len(received)])
                    or written.startswith(received)):
        return (f'the line echoes what is sent ({total} byte(s), all an echo of the request): '
                'a loopback plug, or an adapter with local echo; no device answered')
    sample = received[:16].hex(' ')
    return (f'{total} byte(s) came back, not a {protocol} answer (first: {sample}): another '
            f'device, another baud rate, or noise ({error})')


def link_failed(error: BaseException) -> bool:
    """The error (or one it was raised from) is the link closing, not a missing answer.

    By kind where the kind says it (a transport failure, the OS's connection errors), else
    by the words: the clients raise their own LinkError for a missing answer too."""
    seen: BaseException | None = error
    while seen is not None:
        text = str(seen)
        if isinstance(seen, TransportError | ConnectionError) or 'closed' in text \
                or ' lost' in text:
            return True
        seen = seen.__cause__ or seen.__context__
    return False

