"""kOS homing (no ROS): to the first key frame of a loaded move, else to the begin marks.
A capability of :class:`~.device.KosDevice`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from gimbal_driver_common.device import Homing
from gimbal_driver_common.errors import DeviceTimeout

from .protocol import PlaybackState

if TYPE_CHECKING:
    from .device import KosDevice


class KosHoming(Homing):
    """~/home: a loaded move returns to its first key frame (RapidToFirstKeyFrame until
    MotorsHome); otherwise calibrated joints move to their begin mark (0) and uncalibrated
    joints only get their latched errors cleared (kOS has no homing without calibration)."""

    def __init__(self, device: KosDevice) -> None:
        self.device = device

    def home(
        self, joints: Sequence[str], report: Callable[[str], None], cancelled: threading.Event
    ) -> str:
        device, client = self.device, self.device.client
        device.require_idle()
        if client.playback.loaded:
            return self._first_key_frame(report, cancelled)
        calibrated = [n for n in joints if device.joints[n].address in client.motors
                      and client.motors[device.joints[n].address].calibrated]
        uncalibrated = [n for n in joints if n not in calibrated]
        device.status.clear({device.joints[n].address for n in uncalibrated})
        if calibrated:
            report('moving to the begin marks')
            device.move({n: (device.to_si(n, 0.0), None) for n in calibrated})
            self._wait_at_begin(calibrated, cancelled)
        parts = []
        if calibrated:
            parts.append(f'at the begin mark: {calibrated}')
        if uncalibrated:
            parts.append('not calibrated, errors cleared (no homing without calibration): '
                         f'{uncalibrated}')
        return '; '.join(parts)

    def _first_key_frame(self, report: Callable[[str], None], cancelled: threading.Event) -> str:
        client = self.device.client
        report('returning to the first key frame')
        marker = len(client.playback.history)
        client.commands.rapid_to_first_key_frame()
        if not client.wait_for(
                lambda: PlaybackState.MOTORS_HOME in client.playback.history[marker:]
                or cancelled.is_set(), self.device.settings.playback_timeout):
            raise DeviceTimeout('no MotorsHome notification: the return to the first key '
                                'frame did not complete')
        return 'at the first key frame of the loaded move'

    def _wait_at_begin(self, joints: list[str], cancelled: threading.Event) -> None:
        """Until every joint reads within goal_tolerance of 0 (waits on MotorInfo updates)."""
        device, config = self.device, self.device.motion_config
        tolerance = config.goal_tolerance

        def at_begin() -> bool:
            if cancelled.is_set():
                return True
            motors = device.client.motors
            return all(device.conversion(n).magnitude_to_si(
                abs(motors[device.joints[n].address].position)) <= tolerance for n in joints)

        if not device.client.wait_for(at_begin, config.move_timeout) and not cancelled.is_set():
            raise DeviceTimeout(f'begin marks not reached within {config.move_timeout:g} s')
