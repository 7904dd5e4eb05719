"""Reference driver node for the virtual gimbal: how thin a driver on the base node is."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence

from gimbal_driver_common.diagnostics import Level, RegisterFlag, decode_register
from gimbal_driver_common.ros.base_node import (
    DeviceError,
    DeviceInfo,
    GimbalDriverNode,
    JointSample,
    run_driver,
)
from gimbal_driver_common.ros.diagnostics import StatusPart
from gimbal_driver_common.virtual_gimbal import FAULT_OVERTEMP, JOINTS, VirtualGimbalClient

FAULT_FLAGS = [RegisterFlag(0, 'overtemperature', Level.ERROR, 'motor over temperature')]


class VirtualGimbalNode(GimbalDriverNode):
    DEFAULT_JOINT_NAMES = JOINTS
    DEFAULT_VELOCITY_MAX = (1.5, 1.5)
    DESCRIPTION_NAME = 'virtual_gimbal.urdf'  # share/gimbal_driver_common/urdf/

    def __init__(self) -> None:
        super().__init__('virtual_gimbal')
        self._client: VirtualGimbalClient | None = None
        self._faults = 0

    def declare_device_parameters(self) -> None:
        self.host = self.declare_param('host', '127.0.0.1', 'device address')
        self.port = self.declare_param('port', 4950, 'device TCP port', value_range=(1, 65535))

    def link_description(self) -> str:
        return f'tcp://{self.host}:{self.port}'

    def open_device(self) -> DeviceInfo:
        client = VirtualGimbalClient(self.host, self.port)
        client.open()
        _, model, serial, firmware = client.request('ID').split()
        self._client = client
        return DeviceInfo(model, serial, firmware)

    def close_device(self) -> None:
        if self._client is not None:
            self._client.close()

    def _request(self, line: str) -> str:
        if self._client is None:
            raise DeviceError('not connected')
        try:
            return self._client.request(line)
        except ValueError as exc:
            raise DeviceError(str(exc)) from exc

    def poll_device(self) -> JointSample:
        words = self._request('GET').split()
        pan, tilt, vpan, vtilt = (float(w) for w in words[1:5])
        moving, self._faults = int(words[5]), int(words[6])
        return JointSample(
            positions={'pan': pan, 'tilt': tilt}, velocities={'pan': vpan, 'tilt': vtilt},
            stamp=time.time(), moving={'pan': bool(moving & 1), 'tilt': bool(moving & 2)},
        )

    def send_moves(self, moves: dict[str, tuple[float, float | None]]) -> None:
        for joint, (position, speed) in moves.items():
            self._request(f'MOVE {joint} {position:.6f} {speed or 0.0:.6f}')

    def send_jogs(self, jogs: dict[str, float]) -> None:
        for joint, velocity in jogs.items():
            self._request(f'JOG {joint} {velocity:.6f}')

    def stop_axes(self, joints: Sequence[str] | None) -> None:
        self._request('STOP ' + ' '.join(joints or []))

    def reset_faults(self) -> str:
        self._request('RESET')
        return 'faults cleared'

    def home(
        self, joints: Sequence[str], report: Callable[[str], None], cancelled: threading.Event
    ) -> str:
        self._request('HOME')
        deadline = time.monotonic() + self.move_timeout
        while time.monotonic() < deadline and not cancelled.is_set():
            sample = self.latest_sample
            report('moving to index')
            if sample and all(abs(sample.positions[j]) < 1e-3 for j in JOINTS):
                return 'homed at 0'
            time.sleep(0.05)
        raise DeviceError('homing did not finish')

    def device_status_parts(self) -> list[StatusPart]:
        active = decode_register(self._faults, FAULT_FLAGS, 'faults')
        return [StatusPart.from_flags('device', active, [('fault_bits', hex(self._faults))])]

    def device_errors(self) -> list[str]:
        return [a.flag.name for a in decode_register(self._faults, FAULT_FLAGS)]


def main(argv: list[str] | None = None) -> int:
    return run_driver(VirtualGimbalNode, argv)


assert 1 << FAULT_FLAGS[0].bit == FAULT_OVERTEMP
