"""One control protocol for every simulator: the same verbs, the same consoles, one ready line.

A simulator builds a :class:`SimControl` with its links (the :mod:`sim_server` servers),
a ``state`` snapshot and the device hooks it has (NACKs, fault bits), and registers its
own verbs beside the shared ones. One request line gives one answer line: ``ok``,
``ok <text or JSON>`` or ``error <verb>: <reason>``. Shared verbs::

    drop [SECONDS]              cut the link (TCP clients / the pty); back after SECONDS
    silence on|off              stop answering and streaming, link up
    garbage [N] | garbage hex HEX   N random bytes (default 16) or these bytes on the link
    nack on|off|COMMAND [COUNT] negative-acknowledge every request / the next COUNT of one
    fault NAME|BITS [AXIS]      set device fault bits (names per simulator)
    ignore_motion on|off        ACK move and jog commands but do not act on them
    mute REQUEST [off]          never answer this request (it is received and dropped)
    delay REQUEST SECONDS       answer this request SECONDS late (0: at once again)
    ignore REQUEST SECONDS      for SECONDS, answer this request as the device does but do
                                not act on it (stops and motion messages too; 0: act again)
    clear                       remove every injected fault (silence, NACKs, fault bits,
                                ignore_motion, mute, delay, ignore)
    state                       ok {JSON}: "axes" and the device's own fields
    help                        the verbs of this simulator
    quit                        stop the simulator process

A device without NACKs or a fault register answers ``nack``/``fault`` with an error that
says why. ``mute``/``delay``/``ignore`` take the device's own request names (the
simulator gives them through ``request_names``; an unknown one is answered with the list)
and set the
:class:`~gimbal_driver_common.sim_requests.RequestFaults` the simulator consults
(``request_faults``); ``state`` shows them as ``muted``, ``delayed`` and ``ignored``.

The same :meth:`SimControl.execute` serves the programmatic API, the stdin console and the
TCP console on 127.0.0.1 (:class:`ControlServer`). Each simulator's
``main`` prints one JSON ready line (:func:`ready_line`) naming its port or pty and the
control port, e.g. ``{"ready": "capture_sim", "port": 4949, "control_port": 40123}``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import random
import signal
import socket
import socketserver
import sys
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Protocol, TextIO

from gimbal_driver_common.sim_motion import AxisMotion
from gimbal_driver_common.sim_requests import RequestFaults, resolve_request
from gimbal_driver_common.sim_server import LOOPBACK

DEFAULT_GARBAGE_BYTES = 16
ON_WORDS = ('on', '1', 'true', 'yes')
OFF_WORDS = ('off', '0', 'false', 'no')
#: ``help`` lists the request names of a device that has at most this many
HELP_REQUESTS = 24


class Link(Protocol):
    """What the shared link verbs need of a simulator server (TcpSimServer, PtySimServer)."""

    def drop_link(self, offline_for: float = 0.0) -> None: ...

    def set_silent(self, silent: bool) -> None: ...

    def inject(self, data: bytes) -> None: ...


class ControlError(Exception):
    """A control request cannot be carried out; the message says why."""


#: a verb's handler gets the words after the verb; returns None ("ok") or the answer text
Handler = Callable[[list[str]], 'str | None']


@dataclass
class Verb:
    handler: Handler
    usage: str


def parse_switch(words: Sequence[str]) -> bool:
    """``on``/``off`` (or 1/0, true/false) -> bool; anything else is an error."""
    if len(words) != 1 or words[0].lower() not in ON_WORDS + OFF_WORDS:
        raise ControlError(f'expected on or off, got {" ".join(words) or "nothing"!r}')
    return words[0].lower() in ON_WORDS


def parse_garbage(words: Sequence[str], rng: random.Random) -> bytes:
    """``[N]`` random bytes or ``hex HEX``."""
    if words and words[0].lower() == 'hex':
        try:
            return bytes.fromhex(''.join(words[1:]))
        except ValueError as exc:
            raise ControlError(f'not hex: {" ".join(words[1:])!r}') from exc
    count = int(words[0]) if words else DEFAULT_GARBAGE_BYTES
    if not 0 < count <= 65536:
        raise ControlError(f'byte count {count} outside 1..65536')
    return bytes(rng.randrange(256) for _ in range(count))


@dataclass
class SimControl:
    """The verbs of one simulator; :meth:`execute` runs one request line."""

    name: str
    state: Callable[[], dict]
    links: Sequence[Link] = ()
    #: ``nack`` hook (the words after the verb) or None with the reason in ``no_nack``
    nack: Handler | None = None
    no_nack: str = 'this protocol has no negative acknowledge'
    #: ``fault`` hook (the words after the verb) or None with the reason in ``no_fault``
    fault: Handler | None = None
    no_fault: str = 'this device reports no fault bits'
    fault_names: Iterable[str] = ()
    #: device part of ``clear`` (latched faults, queued NACKs); silence is cleared here
    clear_device: Callable[[], None] | None = None
    #: ``silence`` of the device itself where falling silent is not the link's doing (the
    #: turret: its CAN nodes go quiet, the slcan adapter keeps answering)
    silence: Callable[[bool], None] | None = None
    on_quit: Callable[[], None] | None = None
    #: the simulator's axis models, for ``ignore_motion`` (None: the verb is refused)
    axes: Callable[[], Iterable[AxisMotion]] | None = None
    #: the device's request names ``mute``/``delay``/``ignore`` take (None: refused)
    request_names: Callable[[], Iterable[str]] | None = None
    #: what the simulator consults where it answers a request (mute, delay, ignore)
    request_faults: RequestFaults = field(default_factory=RequestFaults)
    seed: int = 1
    verbs: dict[str, Verb] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._rng = random.Random(self.seed)
        self._lock = threading.Lock()
        self.silenced = False
        shared = {
            'drop': Verb(self._drop, 'drop [SECONDS]'),
            'silence': Verb(self._silence, 'silence on|off'),
            'garbage': Verb(self._garbage, 'garbage [N] | garbage hex HEX'),
            'nack': Verb(self._nack, 'nack on|off|COMMAND [COUNT]'),
            'fault': Verb(self._fault, 'fault NAME|BITS [AXIS]'),
            'ignore_motion': Verb(self._ignore_motion, 'ignore_motion on|off'),
            'mute': Verb(self._mute, 'mute REQUEST [off]'),
            'delay': Verb(self._delay, 'delay REQUEST SECONDS'),
            'ignore': Verb(self._ignore, 'ignore REQUEST SECONDS'),
            'clear': Verb(self._clear, 'clear'),
            'state': Verb(self._state, 'state'),
            'help': Verb(self._help, 'help'),
            'quit': Verb(self._quit, 'quit'),
        }
        clash = set(shared) & set(self.verbs)
        if clash:
            raise ValueError(f'device verbs may not redefine shared ones: {sorted(clash)}')
        self.verbs = {**shared, **self.verbs}

    def add_verb(self, name: str, handler: Handler, usage: str) -> None:
        """Register a device-specific verb (dispatched like the shared ones)."""
        if name in self.verbs:
            raise ValueError(f'verb {name!r} exists')
        self.verbs[name] = Verb(handler, usage)

    # ------------------------------------------------------------------- dispatch
    def execute(self, line: str) -> str:
        """Run one request line; return the answer line (never raises)."""
        words = line.split()
        if not words:
            return 'error: empty request; try help'
        verb, args = words[0].lower(), words[1:]
        entry = self.verbs.get(verb)
        if entry is None:
            return f'error {verb}: unknown verb; try help'
        try:
            with self._lock:
                answer = entry.handler(args)
        except ControlError as exc:
            return f'error {verb}: {exc}'
        except (IndexError, KeyError, ValueError, TypeError) as exc:
            return f'error {verb}: bad arguments {" ".join(args)!r} ({exc!r}); usage: {entry.usage}'
        except (OSError, RuntimeError) as exc:  # a link or device hook failed: say so
            return f'error {verb}: {exc!r}'
        return 'ok' if answer is None else f'ok {answer}'

    # ---------------------------------------------------------------- shared verbs
    def _need_links(self, verb: str) -> None:
        if not self.links:
            raise ControlError(f'{self.name} has no byte link here for {verb}')

    def _drop(self, args: list[str]) -> None:
        seconds = float(args[0]) if args else 0.0
        if seconds < 0:
            raise ControlError(f'seconds {seconds} < 0')
        self._need_links('drop')
        for link in self.links:
            link.drop_link(seconds)

    def _silence(self, args: list[str]) -> None:
        silent = parse_switch(args)
        if self.silence is not None:
            self.silence(silent)
        else:
            self._need_links('silence')
            for link in self.links:
                link.set_silent(silent)
        self.silenced = silent

    def _garbage(self, args: list[str]) -> str:
        data = parse_garbage(args, self._rng)
        self._need_links('garbage')
        for link in self.links:
            link.inject(data)
        return f'{len(data)} bytes'

    def _nack(self, args: list[str]) -> str | None:
        if self.nack is None:
            raise ControlError(f'not applicable to {self.name}: {self.no_nack}')
        if not args:
            raise ControlError('usage: nack on|off|COMMAND [COUNT]')
        return self.nack(args)

    def _fault(self, args: list[str]) -> str | None:
        if self.fault is None:
            raise ControlError(f'not applicable to {self.name}: {self.no_fault}')
        if not args:
            names = ', '.join(self.fault_names) or 'bits'
            raise ControlError(f'usage: fault NAME|BITS [AXIS]; names: {names}')
        return self.fault(args)

    def _ignore_motion(self, args: list[str]) -> str:
        if self.axes is None:
            raise ControlError(f'not applicable to {self.name}: no axis models given')
        ignore = parse_switch(args)
        axes = list(self.axes())
        for axis in axes:
            axis.ignore_commands = ignore
        return f'{len(axes)} axes {"ignore" if ignore else "act on"} move and jog commands'

    def _request(self, verb: str, args: list[str], usage: str) -> str:
        """The device's spelling of the request named in ``args[0]``."""
        if self.request_names is None:
            raise ControlError(f'not applicable to {self.name}: no request names given')
        known = list(self.request_names())
        if not args:
            raise ControlError(f'usage: {usage}; known: {", ".join(sorted(known))}')
        try:
            return resolve_request(args[0], known)
        except LookupError as exc:
            raise ControlError(str(exc)) from exc

    def _mute(self, args: list[str]) -> str:
        name = self._request('mute', args, 'mute REQUEST [off]')
        if len(args) > 2:
            raise ControlError('usage: mute REQUEST [off]')
        muted = parse_switch(args[1:]) if len(args) == 2 else True
        self.request_faults.mute(name, muted)
        return f'{name} {"never answered" if muted else "answered"}'

    def _request_seconds(self, verb: str, args: list[str]) -> tuple[str, float]:
        """``REQUEST SECONDS`` of ``delay`` and ``ignore``: the device's name, seconds >= 0."""
        usage = f'{verb} REQUEST SECONDS'
        name = self._request(verb, args, usage)
        if len(args) != 2:
            raise ControlError(f'usage: {usage}')
        seconds = float(args[1])
        if not (math.isfinite(seconds) and seconds >= 0.0):
            raise ControlError(f'seconds {args[1]!r}: not a finite number >= 0')
        return name, seconds

    def _delay(self, args: list[str]) -> str:
        name, seconds = self._request_seconds('delay', args)
        self.request_faults.delay(name, seconds)
        return f'{name} answered {seconds:g} s late' if seconds else f'{name} answered at once'

    def _ignore(self, args: list[str]) -> str:
        name, seconds = self._request_seconds('ignore', args)
        self.request_faults.ignore(name, seconds)
        return (f'{name} answered but not acted on for {seconds:g} s' if seconds
                else f'{name} acted on again')

    def _clear(self, args: list[str]) -> None:
        self.request_faults.clear()
        if self.silenced:
            self._silence(['off'])
        if self.axes is not None:
            self._ignore_motion(['off'])
        if self.clear_device is not None:
            self.clear_device()

    def _state(self, args: list[str]) -> str:
        state = dict(self.state())
        if self.request_names is not None:
            state.update(self.request_faults.snapshot())
        return json.dumps(state, sort_keys=True, default=str)

    def _help(self, args: list[str]) -> str:
        names = f' (fault names: {", ".join(self.fault_names)})' if self.fault_names else ''
        if self.request_names is not None:
            requests = sorted(self.request_names())
            names += (f' (requests: {", ".join(requests)})' if len(requests) <= HELP_REQUESTS
                      else f' ({len(requests)} request names: `mute` alone lists them)')
        return ' | '.join(verb.usage for verb in self.verbs.values()) + names

    def _quit(self, args: list[str]) -> None:
        if self.on_quit is None:
            raise ControlError('this simulator runs inside another program')
        self.on_quit()


# ------------------------------------------------------------------- consoles
class ControlServer:
    """The TCP console on 127.0.0.1: each line a request, each answer one line."""

    def __init__(self, control: SimControl, port: int = 0) -> None:
        outer = control

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                # socketserver starts one unnamed thread per connection: name it here
                threading.current_thread().name = f'{outer.name}-control-session'
                for raw in self.rfile:
                    line = raw.decode('utf-8', 'replace').strip()
                    if line:
                        self.wfile.write((outer.execute(line) + '\n').encode())

        class Server(socketserver.ThreadingTCPServer):
            allow_reuse_address = True
            daemon_threads = True

        self._server = Server((LOOPBACK, port), Handler)
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True,
                                        name=f'{control.name}-control')

    @property
    def port(self) -> int:
        return self._server.server_address[1]

    def start(self) -> ControlServer:
        self._thread.start()
        return self

    def stop(self) -> None:
        if self._thread.is_alive():
            self._server.shutdown()
        self._server.server_close()


class ControlClient:
    """A connection to a simulator's TCP console (tests, scripts)."""

    def __init__(self, port: int, host: str = LOOPBACK, timeout: float = 10.0) -> None:
        self._sock = socket.create_connection((host, port), timeout=timeout)
        self._file = self._sock.makefile('rwb')

    def command(self, line: str) -> str:
        self._file.write(line.encode() + b'\n')
        self._file.flush()
        return self._file.readline().decode().strip()

    def state(self) -> dict:
        return decode_state(self.command('state'))

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._file.close()
            self._sock.close()

    def __enter__(self) -> ControlClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def control_request(port: int, line: str, timeout: float = 10.0) -> str:
    """One request to a simulator's TCP console; its answer line."""
    with ControlClient(port, timeout=timeout) as client:
        return client.command(line)


def decode_state(answer: str) -> dict:
    """The JSON of a ``state`` answer (raises with the answer if it is an error)."""
    if not answer.startswith('ok {'):
        raise RuntimeError(f'simulator state: {answer}')
    return json.loads(answer[3:])


def control_state(port: int, timeout: float = 10.0) -> dict:
    return decode_state(control_request(port, 'state', timeout))


def serve_lines(control: SimControl, lines: Iterable[str], out: TextIO) -> None:
    """The stdin console: answer each line on ``out`` (ends quietly at end of input, or when
    the terminal refuses a background process)."""
    try:
        for line in lines:
            if line.strip():
                print(control.execute(line), file=out, flush=True)
    except OSError:
        return


# ------------------------------------------------------------------ ready line
def ready_line(name: str, **endpoint: object) -> str:
    """The one JSON line a simulator prints when it accepts connections."""
    return json.dumps({'ready': name, **endpoint})


def parse_ready_line(text: str, name: str | None = None) -> dict | None:
    """The first ready line in ``text`` (of simulator ``name`` if given), or None."""
    for line in text.splitlines():
        line = line.strip()
        if not line.startswith('{'):
            continue
        try:
            data = json.loads(line)
        except ValueError:
            continue
        if isinstance(data, dict) and 'ready' in data and name in (None, data['ready']):
            return data
    return None


def read_ready_line(stream: TextIO, name: str) -> dict:
    """Read a simulator's stdout (a pipe) up to its ready line; return it (raises if the
    output ends first)."""
    for line in stream:
        found = parse_ready_line(line, name)
        if found is not None:
            return found
    raise RuntimeError(f'{name} ended before it was ready')


def run_simulator(control: SimControl, endpoint: dict[str, object], control_port: int = 0,
                  stdin: TextIO | None = None, ready_file: str | None = None) -> None:
    """A simulator's ``main`` loop: TCP console (``control_port`` < 0: none), the stdin
    console, the ready line (also written to ``ready_file`` if given), then wait for
    SIGINT, SIGTERM or ``quit``."""
    stop = threading.Event()
    control.on_quit = stop.set
    server = ControlServer(control, control_port).start() if control_port >= 0 else None
    ready = dict(endpoint)
    if server is not None:
        ready['control_port'] = server.port
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    # started in the background of a shell (`capture_sim &`): reading the terminal must not
    # stop the simulator (SIGTTIN); the read fails instead and the stdin console ends
    signal.signal(signal.SIGTTIN, signal.SIG_IGN)
    line = ready_line(control.name, **ready)
    if ready_file:
        with open(ready_file + '.tmp', 'w', encoding='utf-8') as handle:
            handle.write(line + '\n')
        os.replace(ready_file + '.tmp', ready_file)
    print(line, flush=True)
    console = sys.stdin if stdin is None else stdin
    threading.Thread(target=serve_lines, args=(control, console, sys.stdout), daemon=True,
                     name=f'{control.name}-stdin').start()
    try:
        stop.wait()
    finally:
        if server is not None:
            server.stop()
