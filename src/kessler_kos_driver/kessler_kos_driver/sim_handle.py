"""The kOS simulator in the caller's process, with the faults it can inject (soak)."""

from __future__ import annotations

import math
import random
import time
from pathlib import Path

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_handle import SimHandle


class KesslerSimHandle(SimHandle):
    not_applicable = {'nack': 'kOS answers a bad request with ErrorStatus, injected as '
                              'fault_bits (device error broadcast)'}

    def __init__(self, spec: DriverSpec, workdir: Path) -> None:
        super().__init__(spec, workdir)
        self.sim = None

    def start(self) -> None:
        from kessler_kos_driver.sim import KosSimulator, SimSettings

        self.sim = KosSimulator(SimSettings(password=self.spec.password, precalibrated=True),
                                port=self.port, discovery_port=0).start()
        self.port = self.sim.port
        self._started(self.sim.server, self.sim)

    def device_target(self, joint: str) -> float | None:
        """The motor's target (rotations) in rad: every joint is 2π rad per rotation."""
        addresses = dict(zip(self.spec.joints, self.spec.node_parameters['motor_addresses'],
                             strict=True))
        target = self.sim.device.motors[addresses[joint]].target  # None: no move since rest
        return None if target is None else target * math.tau

    def malformed_frames(self, rng: random.Random) -> None:
        from kessler_kos_driver.protocol import MotorInfo, MotorInfoEntry

        frame = bytearray(MotorInfo([MotorInfoEntry(2, 1.0, 0.0, 100.0, 5.0, 5.0, 10.0)],
                                    more_follows=True).encode())
        frame[len(frame) // 2] ^= 0xFF
        self.server.inject(bytes(frame))

    def lost_frames(self, rng: random.Random) -> None:
        # replies lost for a moment, shorter than the driver's link watchdog
        self.server.set_silent(True)
        time.sleep(0.3)
        self.server.set_silent(False)

    def fault_bits(self, rng: random.Random) -> None:
        from kessler_kos_driver.protocol import ErrorStatus

        with self.sim.device.lock:
            self.sim.device.broadcast(ErrorStatus(16, 1))  # axis fault reported on the slider
