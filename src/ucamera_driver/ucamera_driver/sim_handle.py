"""The U-Camera simulator on a pty in the caller's process, with its faults (soak)."""

from __future__ import annotations

import random
import time
from pathlib import Path

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_handle import SimHandle


class UCameraSimHandle(SimHandle):
    not_applicable = {
        'nack': 'UCSP has no acknowledge/negative acknowledge',
        'fault_bits': 'UCSP reports no fault register (and has no fault reset)',
    }

    def __init__(self, spec: DriverSpec, workdir: Path) -> None:
        super().__init__(spec, workdir)
        self.sim = None

    def start(self) -> None:
        from ucamera_driver.sim import SimConfig, UCameraSim

        self.sim = UCameraSim(SimConfig(), link_path=self.link).start()
        self._started(self.sim.server, self.sim)

    def device_target(self, joint: str) -> float | None:
        """The last commanded angle (rad) of ``joint``, as the gimbal model holds it."""
        return self.sim.model.commanded_angles[self.spec.joints.index(joint)]

    def garbage(self, rng: random.Random) -> None:
        self.sim.inject_noise(rng.randrange(16, 200))

    def lost_frames(self, rng: random.Random) -> None:
        self.sim.drop_frames(0.3)
        time.sleep(1.0)
        self.sim.drop_frames(0.0)

    def malformed_frames(self, rng: random.Random) -> None:
        self.sim.corrupt(next_frames=rng.randrange(1, 8))
