"""Reference driver for the virtual gimbal: a device adapter and a node of a few lines.

Copy its shape for a new driver: the adapter (ROS-free) turns the client's
protocol into the device contract in SI units; the node declares the
parameters and builds the adapter.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence

from gimbal_driver_common.device import (
    Device,
    DeviceInfo,
    Homing,
    JointSample,
    Moves,
    StatusReport,
)
from gimbal_driver_common.diagnostics import Level, RegisterFlag, StatusPart, decode_register
from gimbal_driver_common.errors import DeviceTimeout
from gimbal_driver_common.ros.base_node import GimbalDriverNode
from gimbal_driver_common.ros.run import run_driver
from gimbal_driver_common.virtual_gimbal import FAULT_OVERTEMP, JOINTS, VirtualGimbalClient

FAULT_FLAGS = [RegisterFlag(0, 'overtemperature', Level.ERROR, 'motor over temperature')]
assert 1 << FAULT_FLAGS[0].bit == FAULT_OVERTEMP


class VirtualGimbalDevice(Device, Homing, StatusReport):
    """The virtual gimbal's line protocol as a device (it already speaks SI units)."""

    def __init__(self, host: str, port: int, home_timeout: float = 60.0) -> None:
        super().__init__()
        self.client = VirtualGimbalClient(host, port)
        self.home_timeout = home_timeout
        self._faults = 0
        self._latest: JointSample | None = None
        self.capabilities.homing = self
        self.capabilities.status = self

    def open(self) -> DeviceInfo:
        self.client.open()
        _, model, serial, firmware = self.client.request('ID').split()
        return DeviceInfo(model, serial, firmware)

    def close(self) -> None:
        self.client.close()

    def description(self) -> str:
        return f'tcp://{self.client.stream.host}:{self.client.stream.port}'

    def read(self) -> JointSample:
        words = self.client.request('GET').split()
        pan, tilt, vpan, vtilt = (float(w) for w in words[1:5])
        moving, self._faults = int(words[5]), int(words[6])
        self._latest = JointSample(
            positions={'pan': pan, 'tilt': tilt}, velocities={'pan': vpan, 'tilt': vtilt},
            moving={'pan': bool(moving & 1), 'tilt': bool(moving & 2)})
        return self._latest

    def move(self, moves: Moves) -> None:
        for joint, (position, speed) in moves.items():
            self.client.request(f'MOVE {joint} {position:.6f} {speed or 0.0:.6f}')

    def jog(self, velocities: dict[str, float]) -> None:
        for joint, velocity in velocities.items():
            self.client.request(f'JOG {joint} {velocity:.6f}')

    def stop(self, joints: Sequence[str] | None = None) -> None:
        self.client.request('STOP ' + ' '.join(joints or []))

    def reset_faults(self) -> str:
        self.client.request('RESET')
        return 'faults cleared'

    def home(
        self, joints: Sequence[str], report: Callable[[str], None], cancelled: threading.Event
    ) -> str:
        self.client.request('HOME')
        deadline = time.monotonic() + self.home_timeout
        while time.monotonic() < deadline and not cancelled.is_set():
            report('moving to index')
            sample = self._latest
            if sample and all(abs(sample.positions[j]) < 1e-3 for j in JOINTS):
                return 'homed at 0'
            time.sleep(0.05)
        raise DeviceTimeout('homing did not finish')

    def parts(self) -> list[StatusPart]:
        active = decode_register(self._faults, FAULT_FLAGS, 'faults')
        return [StatusPart.from_flags('device', active, [('fault_bits', hex(self._faults))])]

    def errors(self) -> list[str]:
        return [a.flag.name for a in decode_register(self._faults, FAULT_FLAGS)]


class VirtualGimbalNode(GimbalDriverNode):
    DEFAULT_JOINT_NAMES = JOINTS
    DEFAULT_VELOCITY_MAX = (1.5, 1.5)
    DESCRIPTION_NAME = 'virtual_gimbal.urdf'  # share/gimbal_driver_common/urdf/

    def __init__(self) -> None:
        super().__init__('virtual_gimbal')

    def declare_device_parameters(self) -> None:
        self.host = self.declare_param('host', '127.0.0.1', 'device address')
        self.port = self.declare_param('port', 4950, 'device TCP port', value_range=(1, 65535))

    def make_device(self) -> Device:
        return VirtualGimbalDevice(self.host, self.port, self.config.move_timeout)


def main(argv: list[str] | None = None) -> int:
    return run_driver(VirtualGimbalNode, argv)
