"""The Capture pedestal's guarded procedures (no ROS): levelling on the IMU and the gyro
drift measurement, run by the core's policy (``gimbal_driver_common.guarded``). Each is
handed the device functions (:class:`~.functions.CaptureFunctions`) whose requests it
makes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gimbal_driver_common.device import DeviceProcedure, ProcedureProgress
from gimbal_driver_common.errors import InvalidRequest

if TYPE_CHECKING:
    from .functions import CaptureFunctions


@dataclass
class LevelErrors:
    """Per joint, how far the IMU angle is from its levelling value (reported in degrees,
    as the device counts them)."""

    degrees: dict[str, float]

    def within(self, tolerance: float) -> bool:
        """All within ``tolerance`` rad."""
        return all(abs(math.radians(e)) <= tolerance for e in self.degrees.values())

    def progress(self) -> str:
        return ', '.join(f'{j}: {abs(e):.3f} deg from level' for j, e in self.degrees.items())

    def summary(self) -> str:
        return ', '.join(f'{j} ({abs(e):.3f} deg)' for j, e in self.degrees.items())


class CaptureProcedure(DeviceProcedure):
    """Levelling and the drift measurement share the IMU and run one at a time; a device
    program (scan, loop) keeps them from starting."""

    group = 'a levelling or drift compensation'

    def __init__(self, device: CaptureFunctions) -> None:
        self.device = device

    def busy(self) -> str | None:
        return self.device.programs.running()


class Levelling(CaptureProcedure):
    """IMU_Leveling (4.5.11): the controller turns the joints until the IMU reads its
    levelling values; done once every angle is within ``goal_tolerance`` and the axes
    rest, failed after ``move_timeout``."""

    name = 'levelling'
    cancelled = 'levelling cancelled; axes stopped'
    superseded = 'levelling ended by a newer motion command, which now moves the axes'

    def __init__(self, device: CaptureFunctions, joints: Sequence[str]) -> None:
        super().__init__(device)
        self.joints = list(joints) or list(device.settings.joint_names)
        self.timeout = device.checks.attached_config().move_timeout
        self.timed_out = f'not level within move_timeout {self.timeout:g} s'

    def start(self) -> None:
        self.device.start_leveling(self.joints)

    def poll(self, elapsed: float) -> ProcedureProgress:
        errors = self.device.level_errors(self.joints)
        done = errors.within(self.device.checks.attached_config().goal_tolerance)
        return ProcedureProgress(errors.progress(), 'levelled ' + errors.summary() if done
                                 else None)


class GyroDriftMeasurement(CaptureProcedure):
    """IMU_GyroDriftCompensation (4.5.28): the pedestal holds still for ``duration`` s
    while the controller measures the drift (the spec gives no duration), then the
    result is read; any motion meanwhile makes it untrusted."""

    name = 'the drift measurement'
    cancelled = ('drift measurement cancelled (the controller may still finish it; '
                 '~/reset_gyro_drift clears it)')
    hold_still = True
    period = 0.2

    def __init__(self, device: CaptureFunctions, joints: Sequence[str],
                 duration: float) -> None:
        super().__init__(device)
        self.requested_joints, self.duration = list(joints), duration

    def start(self) -> None:
        if self.requested_joints:
            raise InvalidRequest('the drift compensation takes no joint names (it measures '
                                 f'IMU sensor {self.device.settings.gyro_drift_sensor}, '
                                 'gyro_drift_sensor)')
        self.device.start_gyro_drift()

    def poll(self, elapsed: float) -> ProcedureProgress:
        if elapsed >= self.duration:
            return ProcedureProgress(result=self.device.gyro_drift_result())
        return ProcedureProgress(f'holding still while measuring the gyro drift: '
                                 f'{elapsed:.1f} of {self.duration:g} s')
