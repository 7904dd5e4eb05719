"""The conformance suite against the reference virtual gimbal (node as a process)."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_common.ros.conformance_testing import DriverConformance, SimulatorHandle
from gimbal_driver_common.virtual_gimbal import VirtualGimbal, make_server

# Requests that only read: everything else is a command that can move an axis.
READ_ONLY = ('GET', 'ID')


class InProcessVirtualGimbal(SimulatorHandle):
    """The virtual gimbal served on 127.0.0.1 from the test process; every request line
    is recorded on the device's receive side."""

    def __init__(self) -> None:
        self.server, self.device = make_server(0)
        self.commands: list[str] = []
        handle = self.device.handle

        def recording_handle(line: str) -> str:
            if line.split()[:1] and line.split()[0].upper() not in READ_ONLY:
                self.commands.append(line)
            return handle(line)

        self.device.handle = recording_handle

    def link_parameters(self) -> list[str]:
        return ['host:=127.0.0.1', f'port:={self.server.port}']

    def motion_received(self) -> object:
        return list(self.commands)

    def moving(self, joint: str) -> bool:
        device: VirtualGimbal = self.device
        with device.lock:
            device.step()  # the model integrates lazily: bring it up to now
            return device.axes[joint].moving

    def drop_link(self, seconds: float) -> None:
        self.server.drop_link(seconds)

    def close(self) -> None:
        self.server.stop()


class TestVirtualGimbalConformance(DriverConformance):
    __test__ = True
    package = 'gimbal_driver_common'
    node_executable = 'virtual_gimbal_node'
    node_name = 'virtual_gimbal'
    joints = ('pan', 'tilt')
    small_move = {'pan': 0.4, 'tilt': -0.2}
    far_move = ('pan', -2.5, 0.3)
    jog = ('tilt', 0.2)
    tolerance = 0.011
    preset_index = 4
    scan = dict(pattern='sector', pan_min=-0.2, pan_max=0.2, speed=1.2)

    def start_simulator(self, workdir: Path, domain: int) -> SimulatorHandle:
        return InProcessVirtualGimbal()
