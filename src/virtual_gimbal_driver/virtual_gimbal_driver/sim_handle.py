"""The virtual gimbal's in-process simulator handle (soak, bench, conformance suite)."""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_control import SimControl
from gimbal_driver_common.sim_handle import LibraryWarning, SimHandle

from .protocol import MOTION, READS, verb
from .sim import make_control, make_server


class VirtualGimbalSim(SimHandle):
    """The reference virtual gimbal's line-protocol simulator on TCP. The receive side logs
    request lines; ``ID`` and ``GET`` only read."""

    not_applicable = {
        'nack': 'the line protocol answers ERR only to a request; an unsolicited ERR line '
                'would be a framing fault (covered by garbage/malformed)',
        'lost_frames': 'one reply per request over TCP; a lost reply is a silence (covered)',
    }
    stop_requests = ('STOP',)
    stop_request = 'STOP'

    def __init__(self, spec: DriverSpec, workdir: Path, process_tests: bool = False) -> None:
        super().__init__(spec, workdir, process_tests)
        self.device: Any = None
        self._controls: SimControl | None = None

    def start(self) -> None:
        server, self.device = make_server(self.port)
        handle = self.device.handle

        def recorded(line: str) -> str | None:
            self.record(line.strip())
            return handle(line)

        self.device.handle = recorded
        self._controls = make_control(server, self.device)
        self.port = server.port
        self._started(server, server)

    def changing(self, request: str) -> bool:
        return verb(request) not in READS

    def motion(self, request: str) -> bool:
        return verb(request) in MOTION

    def moving(self, joint: str) -> bool:
        with self.device.lock:
            self.device.step()  # the model integrates lazily: bring it up to now
            return self.device.axes[joint].moving

    def controls(self) -> SimControl:
        if self._controls is None:
            raise RuntimeError(f'{self.spec.name}: the simulator is not started')
        return self._controls

    def device_target(self, joint: str) -> float | None:
        # a MOVE line sets the target as it is handled
        return self.device.axes[joint].target

    def axis_limits(self, joint: str) -> tuple[float, float]:
        axis = self.device.axes[joint]  # rad
        return axis.move_speed, axis.acceleration

    def malformed_frames(self, rng: random.Random) -> None:
        # a reply line that does not parse (no newline: it prefixes the next real reply)
        self.server.inject(b'POS nan x')

    def fault_bits(self, rng: random.Random) -> None:
        self.control('fault overtemp')

    def provoke_library_warning(self) -> LibraryWarning:
        # a line nobody asked for: the client discards it before its next request (if it
        # lands inside an exchange it is read as a reply instead: the caller tries again)
        self.control('garbage hex ' + b'NOISE\n'.hex())
        return LibraryWarning('virtual_gimbal_driver.client', 'NOISE')
