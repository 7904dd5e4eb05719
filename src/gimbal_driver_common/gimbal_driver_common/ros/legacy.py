"""Transition shim: runs a driver written against the old hook-based base node.

A driver not yet moved onto the device contract subclasses
:class:`HookedDriverNode`; its node hooks (open_device, poll_device, send_moves,
...) are wrapped into a :class:`Device` by :class:`NodeHooksDevice`. Delete this
module once every driver has a device adapter.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

from gimbal_driver_common.device import (
    Device,
    DeviceInfo,
    DevicePresets,
    DeviceScans,
    Homing,
    JointSample,
    Moves,
    StatusReport,
)
from gimbal_driver_common.diagnostics import StatusPart
from gimbal_driver_common.errors import DeviceRefused, Unsupported
from gimbal_driver_common.policies import DRIVER_SCAN_PATTERNS, scan_joints
from gimbal_driver_common.ros.base_node import GimbalDriverNode
from gimbal_driver_common.scan import ScanRequest
from gimbal_driver_common.watchdog import JogWatchdog

DeviceError = DeviceRefused


class _Hooks(Homing, DevicePresets, DeviceScans, StatusReport):
    """The node's optional hooks as capability objects."""

    def __init__(self, node: HookedDriverNode) -> None:
        self.node = node
        self.patterns = tuple(p for p in node.SCAN_PATTERNS if p not in DRIVER_SCAN_PATTERNS
                              or type(node).start_device_scan
                              is not HookedDriverNode.start_device_scan)

    def home(self, joints, report, cancelled):
        return self.node.home(joints, report, cancelled)

    def handles(self, index: int) -> bool:
        return self.node.DEVICE_PRESETS

    def set(self, index, name, positions):
        return self.node.device_set_preset(index, name, positions)

    def goto(self, index, speed):
        return self.node.device_goto_preset(index, speed)

    def list(self):
        return [(p.index, p.name, dict(zip(p.joint_names, p.positions, strict=False)))
                for p in self.node.device_list_presets()]

    def clear(self, index):
        return self.node.device_clear_preset(index)

    def start(self, request: ScanRequest) -> str:
        message = self.node.start_device_scan(request)
        if message is None:
            raise Unsupported(f'pattern {request.pattern!r} is not a device scan')
        return message

    def stop(self) -> None:
        self.node.stop_device_scan()

    def parts(self) -> list[StatusPart]:
        return self.node.device_status_parts()

    def mode(self) -> str:
        return self.node.device_mode()

    def errors(self) -> list[str]:
        return self.node.device_errors()

    def axis_details(self, joint: str) -> dict[str, object]:
        return self.node.axis_details(joint)


class NodeHooksDevice(Device):
    def __init__(self, node: HookedDriverNode) -> None:
        super().__init__()
        self.node = node
        self.streamed = node.STREAMED
        hooks = _Hooks(node)
        overridden = type(node).home is not HookedDriverNode.home
        self.capabilities.homing = hooks if overridden else None
        self.capabilities.presets = hooks if node.DEVICE_PRESETS else None
        self.capabilities.scans = hooks if hooks.patterns else None
        self.capabilities.status = hooks

    def open(self) -> DeviceInfo:
        return self.node.open_device()

    def close(self) -> None:
        self.node.close_device()

    def read(self) -> JointSample | None:
        return self.node.poll_device()

    def move(self, moves: Moves) -> None:
        self.node.send_moves(moves)

    def move_relative(self, offsets: dict[str, float], moves: Moves) -> bool:
        return self.node.send_relative_moves(offsets, moves)

    def jog(self, velocities: dict[str, float]) -> None:
        self.node.send_jogs(velocities)

    def stop(self, joints: Sequence[str] | None = None) -> None:
        self.node.stop_axes(joints)

    def reset_faults(self) -> str:
        return self.node.reset_faults()

    def refusal(self, joints: Sequence[str]) -> str | None:
        return self.node.axis_refusal(joints)

    def link_healthy(self) -> bool:
        return self.node.link_healthy()

    def expected_rate(self, publish_rate: float) -> float:
        return self.node.expected_joint_rate()

    def description(self) -> str:
        return self.node.link_description()


class HookedDriverNode(GimbalDriverNode):
    """The old hook surface on top of the new node (see module docstring)."""

    DEVICE_PRESETS = False
    STREAMED = False

    def make_device(self) -> Device:
        return NodeHooksDevice(self)

    # hooks with their old defaults
    def open_device(self) -> DeviceInfo:
        raise NotImplementedError

    def close_device(self) -> None:
        pass

    def poll_device(self) -> JointSample | None:
        raise NotImplementedError

    def link_healthy(self) -> bool:
        return True

    def send_moves(self, moves: Moves) -> None:
        raise NotImplementedError

    def send_relative_moves(self, offsets: dict[str, float], moves: Moves) -> bool:
        return False

    def send_jogs(self, jogs: dict[str, float]) -> None:
        raise NotImplementedError

    def stop_axes(self, joints: Sequence[str] | None) -> None:
        raise NotImplementedError

    def reset_faults(self) -> str:
        raise Unsupported('this device has no fault-reset command')

    def home(self, joints: Sequence[str], report: Callable[[str], None],
             cancelled: threading.Event) -> str:
        raise Unsupported('this device has no homing routine')

    def device_status_parts(self) -> list[StatusPart]:
        return []

    def device_mode(self) -> str:
        return ''

    def axis_details(self, joint: str) -> dict[str, object]:
        return {}

    def device_errors(self) -> list[str]:
        return []

    def device_set_preset(self, index, name, positions) -> str:
        raise DeviceRefused('no device presets')

    def device_goto_preset(self, index: int, speed: float) -> str:
        raise DeviceRefused('no device presets')

    def device_list_presets(self) -> list:
        raise DeviceRefused('no device presets')

    def device_clear_preset(self, index: int | None) -> str:
        raise DeviceRefused('no device presets')

    def start_device_scan(self, request: ScanRequest) -> str | None:
        return None

    def stop_device_scan(self) -> None:
        pass

    def axis_refusal(self, joints: Sequence[str]) -> str | None:
        return None

    def expected_joint_rate(self) -> float:
        return self.config.publish_rate

    def link_description(self) -> str:
        return ''

    # old helpers, now views of the controller
    @property
    def device_info(self) -> DeviceInfo:
        return self.controller.device_info if self.controller else DeviceInfo()

    @property
    def commanded_targets(self) -> dict[str, float]:
        return self.controller.commanded_targets if self.controller else {}

    @property
    def jog_watchdog(self) -> JogWatchdog | None:
        return self.controller.watchdog if self.controller else None

    @property
    def preset_store(self):
        return self.motion.store if self.motion else None

    @property
    def _move_generation(self) -> int:
        return self.controller.motion_generation if self.controller else 0

    @_move_generation.setter
    def _move_generation(self, value: int) -> None:
        if self.controller:
            self.controller.motion_generation = value

    @property
    def _scan_thread(self) -> threading.Thread | None:
        return self.motion._scan_thread if self.motion else None

    def notify_new_data(self) -> None:
        if self.controller:
            self.controller.device.notify_data()

    def add_periodic(self, period: float, callback: Callable[[], object]) -> None:
        self.periodic.add(period, callback)

    def set_periodic_period(self, callback: Callable[[], object], period: float) -> None:
        self.periodic.set_period(callback, period)

    def _stop_scan_silently(self) -> None:
        if self.motion:
            self.motion.preempt()

    def scan_joints(self) -> list[str]:
        return scan_joints(self.config)

    def _stop_quietly(self, joints: Sequence[str] | None) -> None:
        if self.controller:
            self.controller.stop_joints(joints)
