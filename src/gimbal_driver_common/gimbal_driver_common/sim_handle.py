"""A driver's simulator inside the calling process: its faults and its receive side.

The soak (``scripts/soak.py``), the generic benchmark (``bench/``) and the cross-driver
process tests (``tests/test_ros_properties.py``, ``tests/test_crash_safety.py``) start the
simulator in their own process so they reach its device model and fault API directly; the
node runs as a separate process connected by :meth:`SimHandle.node_parameters`. Each driver
package subclasses :class:`SimHandle` and names the subclass in its registry spec
(``DriverSpec.sim_handle``); the reference virtual gimbal's is
``virtual_gimbal_driver.sim_handle.VirtualGimbalSim``.
:func:`make_handle` builds the one a spec names.

The receive side is a log of every request the device model handled (:meth:`SimHandle.requests`),
each classified by the subclass as

* *changing*: anything that moves, stops or changes the device (a refused ROS request must
  send none of these), and
* *motion*: what moves or stops an axis (a node taking over a device in motion must not
  redirect or stop the move where the protocol lets it stay silent).

A fault is a method that injects it and returns when the fault has *healed* (the link is
back, the device answers again); the soak times joint_states from that moment. The shared
faults (link drop, silence, garbage) go through the simulator's control protocol
(:mod:`gimbal_driver_common.sim_control`, :meth:`SimHandle.control`), the same verbs its
console and TCP control port take; so do the request faults :meth:`SimHandle.mute`,
:meth:`SimHandle.delay`, :meth:`SimHandle.ignore` and :meth:`SimHandle.clear`. ``link``
marks faults that interrupt joint_states (link drop, silence, restart). Faults a protocol
cannot carry are listed in ``not_applicable`` with the reason.
"""

from __future__ import annotations

import enum
import random
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gimbal_driver_common.registry import DriverSpec, parameter_text, resolve
from gimbal_driver_common.sim_control import ControlError, SimControl

#: seconds a link stays down / silent; long enough for each driver's link watchdog to notice
LINK_DOWN_S = 2.0
SILENCE_S = 3.0

#: fault name (= the method that injects it) -> needs ~/reset_faults afterwards
OPTIONAL_FAULTS = {'lost_frames': False, 'malformed_frames': False, 'nack': False,
                   'fault_bits': True}


@dataclass
class Fault:
    name: str
    inject: Callable[[random.Random], None]  # returns once the fault has healed
    link: bool = False                       # interrupts joint_states (resume time measured)
    reset_faults: bool = False               # needs ~/reset_faults to clear


class Takeover(enum.Enum):
    """What happens to a slow move when its node is SIGKILLed and a new node starts."""

    #: the device runs the move on; the new node sends no motion command of its own
    RUNS_ON = 'runs on'
    #: the device runs the move on until the new node connects: the protocol's connect
    #: handshake itself stops the axes (Capture COM_Connect, spec 4.6.2: "position mode,
    #: relative with speed set to 0")
    STOPS_ON_CONNECT = 'stops on connect'
    #: the slow move is the driver's own ramp of set-points (U-Camera has no speed input):
    #: the device stops at the last set-point the killed node sent
    STOPS_WITH_NODE = 'stops with the node'


@dataclass(frozen=True)
class LibraryWarning:
    """A WARNING the driver's library code (client, adapter, the core's session) logs
    through :mod:`logging`, not the node: the log conformance test looks for it on
    /rosout (``gimbal_driver_testing.log_conformance``)."""

    #: the Python logger that logs it (its name starts the line on /rosout)
    logger: str
    #: a piece of its text
    text: str


class SimHandle:
    """One in-process simulator; subclasses build it (:meth:`start`), know its faults and
    classify the requests it receives.

    ``process_tests``: the settings the process tests (each package's conformance test,
    ``tests/test_ros_properties.py``, ``tests/test_crash_safety.py``) run with: quick device
    timings, a far move (:attr:`far_move`) that lasts tens of seconds on the device, and
    node parameters (:attr:`process_test_parameters`) that leave a move the device runs
    alone when a node starts.
    """

    #: fault name -> why this protocol cannot carry it
    not_applicable: dict[str, str] = {}
    #: (joint, target, speed) of a slow far move the device runs for tens of seconds with
    #: ``process_tests`` (the speed is the device's where it has no speed input)
    far_move: tuple[str, float, float] = ('pan', 2.5, 0.25)
    #: a reachable MoveTo goal (joint -> rad/m) after a takeover
    takeover_goal: Mapping[str, float] = {'pan': 0.2, 'tilt': -0.1}
    takeover: Takeover = Takeover.RUNS_ON
    #: preset calls that are valid with nothing stored: (service, index; None = any index),
    #: for presets the device keeps itself
    valid_preset_calls: tuple[tuple[str, int | None], ...] = ()
    #: node parameters that replace the spec's with ``process_tests`` (None: leave it unset)
    process_test_parameters: Mapping[str, Any] = {}
    #: the device's names (as ``mute``/``delay``/``ignore`` take them) of every message a
    #: stop sends, and the one among them that stops a jogging axis (the stop conformance)
    stop_requests: tuple[str, ...] = ()
    stop_request: str = ''

    def __init__(self, spec: DriverSpec, workdir: Path, process_tests: bool = False) -> None:
        self.spec = spec
        self.workdir = workdir
        self.process_tests = process_tests
        self.port = 0
        self.link = spec.link_values(workdir)['link']
        self._hooks: list[Callable[[], None]] = []
        self._server: Any = None
        self._running: Any = None
        self._lock = threading.Lock()
        self._requests: list[str] = []
        #: bytes-level receptions (every read of the server, the node's polls included)
        self.receptions = 0

    # lifecycle of the simulator
    def start(self) -> None:
        """Build and start the simulator; call :meth:`_started` with its TCP/pty server
        (where the receive hooks go) and what :meth:`stop` stops. A TCP simulator binds
        ``self.port`` (0 the first time) and sets it to the bound port."""
        raise NotImplementedError

    def stop(self) -> None:
        self._running.stop()

    def restart(self, rng: random.Random) -> None:
        """Power-cycle: the old simulator goes away, a new one serves the same address."""
        self.stop()
        time.sleep(rng.uniform(0.2, 1.0))
        self.start()

    @property
    def server(self) -> Any:  # TcpSimServer | PtySimServer
        return self._server

    def controls(self) -> SimControl:
        """The running simulator's control verbs (:mod:`gimbal_driver_common.sim_control`)."""
        raise NotImplementedError

    def control(self, line: str) -> str:
        """Run one control request; the answer after ``ok`` (ControlError on ``error``)."""
        answer = self.controls().execute(line)
        if answer != 'ok' and not answer.startswith('ok '):
            raise ControlError(answer)
        return answer[3:]

    def add_receive_hook(self, hook: Callable[[], None]) -> None:
        """A hook on this and every later (restarted) server."""
        self._hooks.append(hook)
        self.server.add_receive_hook(hook)

    def _started(self, server: Any, running: Any) -> None:
        """Record a (re)started simulator; the receive hooks move to its new server."""
        self._server, self._running = server, running
        server.add_receive_hook(self._received)
        for hook in self._hooks:
            server.add_receive_hook(hook)

    def _received(self) -> None:
        with self._lock:
            self.receptions += 1

    def close(self) -> None:
        """Stop the simulator (the conformance rig's name for :meth:`stop`)."""
        if self._running is not None:
            self.stop()

    def node_parameters(self) -> dict[str, Any]:
        """The spec's parameters for this simulator (port, pty path, password file), with
        :attr:`process_test_parameters` applied under ``process_tests``."""
        parameters = self.spec.parameters(self.workdir, self.port)
        if self.process_tests:
            parameters.update(self.process_test_parameters)
        return {name: value for name, value in parameters.items() if value is not None}

    def link_parameters(self) -> list[str]:
        """:meth:`node_parameters` as ``name:=value`` for ``--ros-args -p``."""
        return [f'{name}:={parameter_text(value)}'
                for name, value in self.node_parameters().items()]

    # the receive side
    def record(self, request: str, detail: str = '') -> None:
        """Log one request the device model handled (subclasses wrap the model's handler).
        ``detail`` tells apart requests of one name (Capture's ``axis 2``): the timed log
        of the silent-request conformance keeps it, :meth:`requests` has the names."""
        with self._lock:
            self._requests.append(request)

    def requests(self) -> list[str]:
        with self._lock:
            return list(self._requests)

    def mark(self) -> int:
        """A position in the request log, for :meth:`changes_since`/:meth:`motions_since`."""
        with self._lock:
            return len(self._requests)

    def changes_since(self, mark: int) -> list[str]:
        return [r for r in self.requests()[mark:] if self.changing(r)]

    def motions_since(self, mark: int) -> list[str]:
        return [r for r in self.requests()[mark:] if self.motion(r)]

    def motion_received(self) -> object:
        """A snapshot of the motion requests so far: two equal snapshots mean nothing that
        moves an axis reached the device in between."""
        return len(self.motions_since(0))

    def changing(self, request: str) -> bool:
        """Whether a logged request moves, stops or changes the device."""
        raise NotImplementedError

    def motion(self, request: str) -> bool:
        """Whether a logged request moves or stops an axis."""
        raise NotImplementedError

    def moving(self, joint: str) -> bool:
        """Whether the device itself (not the driver's view) has ``joint`` in motion."""
        raise NotImplementedError

    def device_target(self, joint: str) -> float | None:
        """The target the device model holds for ``joint``, in the joint's unit (rad/m);
        the generic benchmark watches it for commands arriving. None: not known."""
        raise NotImplementedError(f'{type(self).__name__} does not expose device targets')

    def axis_limits(self, joint: str) -> tuple[float, float]:
        """(speed limit of a position move now, acceleration) of ``joint``'s axis on the
        device model, in the joint's units (rad/s and rad/s², m/s and m/s²): what the
        tracking benchmark compares its error with."""
        raise NotImplementedError(f'{type(self).__name__} does not expose its axis limits')

    # faults every server has
    def drop_link(self, seconds: float) -> None:
        """Cut the link to the node and refuse a new one for ``seconds`` (returns at once)."""
        self.control(f'drop {seconds}')

    def mute(self, request: str) -> None:
        """Never answer ``request`` (the device's own name for it, as the ``mute`` verb
        takes it): the simulator receives and logs it, then drops it."""
        self.control(f'mute {request}')

    def delay(self, request: str, seconds: float) -> None:
        """Answer ``request`` ``seconds`` late; other requests are answered at once."""
        self.control(f'delay {request} {seconds!r}')

    def ignore(self, request: str, seconds: float) -> None:
        """For ``seconds``, answer ``request`` as the device does but do not act on it (a
        stop or motion message the device drops)."""
        self.control(f'ignore {request} {seconds!r}')

    def clear(self) -> None:
        """Remove every injected fault (mutes, delays and ignores included): ``clear``."""
        self.control('clear')

    def link_drop(self, rng: random.Random) -> None:
        self.drop_link(LINK_DOWN_S)
        time.sleep(LINK_DOWN_S)

    def silence(self, rng: random.Random) -> None:
        self.control('silence on')
        time.sleep(SILENCE_S)
        self.control('silence off')

    def garbage(self, rng: random.Random) -> None:
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(16, 200)))
        self.control(f'garbage hex {data.hex()}')

    def provoke_library_warning(self) -> LibraryWarning:
        """Make the driver's library code log a WARNING on a real path (a link drop, bytes
        that do not frame, a device event) and say what it logs. Called again while the
        line does not show (an injection can race the driver's own exchange)."""
        raise NotImplementedError(f'{type(self).__name__} names no library warning')

    def faults(self) -> list[Fault]:
        """The faults every server has, plus those the subclass implements (a method named
        in OPTIONAL_FAULTS)."""
        faults = [Fault('link_drop', self.link_drop, link=True),
                  Fault('silence', self.silence, link=True),
                  Fault('garbage', self.garbage),
                  Fault('sim_restart', self.restart, link=True)]
        for name, needs_reset in OPTIONAL_FAULTS.items():
            inject = getattr(self, name, None)
            if inject is not None:
                faults.append(Fault(name, inject, reset_faults=needs_reset))
        return faults

    def joint_range(self, joint: str) -> tuple[float, float]:
        """A valid joint_command target range for ``joint`` (rad/m)."""
        return self.spec.soak.joint_ranges.get(joint, self.spec.soak.safe_range)


def make_handle(spec: DriverSpec, workdir: Path, process_tests: bool = False) -> SimHandle:
    """The in-process simulator handle ``spec.sim_handle`` names (not started yet)."""
    return resolve(spec.sim_handle)(spec, workdir, process_tests=process_tests)
