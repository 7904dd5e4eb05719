"""The turret simulator behind an slcan pty in the caller's process, with its faults (soak)."""

from __future__ import annotations

import random
import time
from pathlib import Path

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_handle import SILENCE_S, SimHandle


class CanaeroSimHandle(SimHandle):
    not_applicable = {'nack': 'CANaerospace services have no negative acknowledge the turret '
                              'sends; its error path is the EED event, injected as fault_bits'}

    def __init__(self, spec: DriverSpec, workdir: Path) -> None:
        super().__init__(spec, workdir)
        self.simulator = None

    def start(self) -> None:
        from canaero_turret_driver.sim import SimConfig, SlcanSession, TurretSimulator
        from gimbal_driver_common.sim_server import PtySimServer

        self.simulator = TurretSimulator(SimConfig())
        simulator = self.simulator
        server = PtySimServer(lambda: SlcanSession(simulator), link_path=self.link).start()
        self._started(server, server)

    def silence(self, rng: random.Random) -> None:
        self.simulator.silence_all(SILENCE_S)
        time.sleep(SILENCE_S)

    def lost_frames(self, rng: random.Random) -> None:
        self.simulator.lose_frames(rng.choice(('yaw_position', 'pitch_position')),
                                   rng.randrange(1, 6))

    def malformed_frames(self, rng: random.Random) -> None:
        self.simulator.send_malformed(rng.randrange(1, 5))

    def fault_bits(self, rng: random.Random) -> None:
        axis = rng.choice(tuple(self.simulator.axes))
        self.simulator.set_axis_fault(axis, True)
        time.sleep(0.5)
        self.simulator.set_axis_fault(axis, False)  # the cause goes away; reset_faults follows
