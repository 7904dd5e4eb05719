"""The Capture simulator in the caller's process, with the faults it can inject (soak)."""

from __future__ import annotations

import random
from pathlib import Path

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_handle import SimHandle


class CaptureSimHandle(SimHandle):
    def __init__(self, spec: DriverSpec, workdir: Path) -> None:
        super().__init__(spec, workdir)
        self.sim = None

    def start(self) -> None:
        from capture_driver.sim import CaptureSimulator, PedestalModel

        self.sim = CaptureSimulator(PedestalModel(), tcp_port=self.port).start()
        self.port = self.sim.tcp.port
        self._started(self.sim.tcp, self.sim)

    def lost_frames(self, rng: random.Random) -> None:
        self.sim.model.lose_replies(rng.randrange(1, 4))

    def malformed_frames(self, rng: random.Random) -> None:
        from capture_driver.protocol import COMMANDS, DataType, Frame, encode_value

        opcode = COMMANDS['MOT_GetLoadPosition'].opcode
        frame = bytearray(Frame(0, 1, opcode, encode_value(DataType.F32, 12.5)).encode())
        frame[-1] ^= 0x5A  # checksum no longer matches
        self.server.inject(bytes(frame))

    def nack(self, rng: random.Random) -> None:
        self.sim.model.nack_next(count=rng.randrange(1, 4))

    def fault_bits(self, rng: random.Random) -> None:
        self.sim.model.inject_fault(rng.choice((1, 2)), 'over_current')
