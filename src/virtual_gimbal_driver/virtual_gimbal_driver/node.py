"""``virtual_gimbal_driver_node``: the reference driver's node, a few lines on the base node."""

from __future__ import annotations

from gimbal_driver_common.device import Device
from gimbal_driver_common.ros.base_node import GimbalDriverNode
from gimbal_driver_common.ros.run import run_driver

from .device import VirtualGimbalDevice
from .protocol import JOINTS


class VirtualGimbalNode(GimbalDriverNode):
    DEFAULT_JOINT_NAMES = JOINTS
    DEFAULT_VELOCITY_MAX = (1.5, 1.5)

    def __init__(self) -> None:
        super().__init__('virtual_gimbal_driver')

    def declare_device_parameters(self) -> None:
        self.host = self.declare_param('host', '127.0.0.1', 'device address')
        self.port = self.declare_param('port', 4950, 'device TCP port', value_range=(1, 65535))
        self.request_timeout = self.declare_param(
            'request_timeout', 1.0, 's to wait for the reply line to a request (ID, GET, MOVE, '
            'JOG, STOP, HOME, RESET)', value_range=(0.05, 10.0))

    def make_device(self) -> Device:
        return VirtualGimbalDevice(self.host, self.port, self.config.move_timeout,
                                   request_timeout=self.request_timeout)


def main(argv: list[str] | None = None) -> int:
    return run_driver(VirtualGimbalNode, argv)
