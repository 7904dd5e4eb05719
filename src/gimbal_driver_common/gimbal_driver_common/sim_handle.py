"""A driver's simulator inside the calling process, with the faults it can inject.

The soak (``scripts/soak.py``) and the generic benchmark (``bench/``) start the simulator
in their own process so they reach its device model and fault API directly; the node runs
as a separate process connected by :meth:`SimHandle.node_parameters`. Each driver package
subclasses :class:`SimHandle` and names the subclass in its registry spec
(``DriverSpec.sim_handle``); the reference virtual gimbal's is :class:`VirtualGimbalSim`.

A fault is a method that injects it and returns when the fault has *healed* (the link is
back, the device answers again); the soak times joint_states from that moment. ``link``
marks faults that interrupt joint_states (link drop, silence, restart). Faults a protocol
cannot carry are listed in ``not_applicable`` with the reason.
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gimbal_driver_common.registry import DriverSpec

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


class SimHandle:
    """One in-process simulator; subclasses build it (:meth:`start`) and know its faults."""

    #: fault name -> why this protocol cannot carry it
    not_applicable: dict[str, str] = {}

    def __init__(self, spec: DriverSpec, workdir: Path) -> None:
        self.spec = spec
        self.workdir = workdir
        self.port = 0
        self.link = spec.link_values(workdir)['link']
        self._hooks: list[Callable[[], None]] = []
        self._server: Any = None
        self._running: Any = None

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

    def add_receive_hook(self, hook: Callable[[], None]) -> None:
        """A hook on this and every later (restarted) server."""
        self._hooks.append(hook)
        self.server.add_receive_hook(hook)

    def _started(self, server: Any, running: Any) -> None:
        """Record a (re)started simulator; the receive hooks move to its new server."""
        self._server, self._running = server, running
        for hook in self._hooks:
            server.add_receive_hook(hook)

    def node_parameters(self) -> dict[str, Any]:
        """The spec's link parameters for this simulator (port, pty path, password file)."""
        return self.spec.parameters(self.workdir, self.port)

    def device_target(self, joint: str) -> float | None:
        """The target the device model holds for ``joint``, in the joint's unit (rad/m);
        the generic benchmark watches it for commands arriving. None: not known."""
        raise NotImplementedError(f'{type(self).__name__} does not expose device targets')

    # faults every server has
    def drop_link(self, rng: random.Random) -> None:
        self.server.drop_link(LINK_DOWN_S)
        time.sleep(LINK_DOWN_S)

    def silence(self, rng: random.Random) -> None:
        self.server.set_silent(True)
        time.sleep(SILENCE_S)
        self.server.set_silent(False)

    def garbage(self, rng: random.Random) -> None:
        self.server.inject(bytes(rng.randrange(256) for _ in range(rng.randrange(16, 200))))

    def faults(self) -> list[Fault]:
        """The faults every server has, plus those the subclass implements (a method named
        in OPTIONAL_FAULTS)."""
        faults = [Fault('link_drop', self.drop_link, link=True),
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


class VirtualGimbalSim(SimHandle):
    """The reference virtual gimbal's line-protocol simulator on TCP."""

    not_applicable = {
        'nack': 'the line protocol answers ERR only to a request; an unsolicited ERR line '
                'would be a framing fault (covered by garbage/malformed)',
        'lost_frames': 'one reply per request over TCP; a lost reply is a silence (covered)',
    }

    def __init__(self, spec: DriverSpec, workdir: Path) -> None:
        super().__init__(spec, workdir)
        self.device: Any = None

    def start(self) -> None:
        from gimbal_driver_common.virtual_gimbal import make_server

        server, self.device = make_server(self.port)
        self.port = server.port
        self._started(server, server)

    def device_target(self, joint: str) -> float | None:
        # a MOVE line sets the target as it is handled
        return self.device.axes[joint].target

    def malformed_frames(self, rng: random.Random) -> None:
        # a reply line that does not parse (no newline: it prefixes the next real reply)
        self.server.inject(b'POS nan x')

    def fault_bits(self, rng: random.Random) -> None:
        with self.device.lock:
            self.device.faults = 1  # FAULT_OVERTEMP
