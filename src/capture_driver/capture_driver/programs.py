"""Which motion programs of the Capture controller's own run (no ROS): its scan, its preset
loop, its target loop. One object, held by :class:`~.device.CaptureDevice` and handed to
the parts that start, end or ask about them (the device functions, the scan and homing
capabilities), so none of them reads another's flags.
"""

from __future__ import annotations

from .client import CaptureClient

#: SYS register bits (4.10): scan, preset looping, target looping active
SCANNING_BIT, PRESET_LOOPING_BIT, TARGET_LOOPING_BIT = 2, 3, 4


class DevicePrograms:
    """The device's own motion programs: what the driver started or the registers show.

    A motion command ends them first (:meth:`leave`): the controller refuses motor writes
    with 0xA6 while it scans (4.3).
    """

    def __init__(self, client: CaptureClient) -> None:
        self._client = client
        self.scanning = False
        self.preset_looping = False
        self.target_looping = False

    @property
    def any(self) -> bool:
        return self.scanning or self.preset_looping or self.target_looping

    def clear(self) -> None:
        """None runs (a stop of everything, an emergency stop)."""
        self.scanning = self.preset_looping = self.target_looping = False

    def from_system_state(self, sys_state: int) -> None:
        """What the SYS register the status poll read says runs."""
        self.scanning = bool(sys_state & (1 << SCANNING_BIT))
        self.preset_looping = bool(sys_state & (1 << PRESET_LOOPING_BIT))
        self.target_looping = bool(sys_state & (1 << TARGET_LOOPING_BIT))

    def running(self) -> str | None:
        """Why the device is busy with a motion program of its own, or None."""
        if self.scanning:
            return 'a scan is running; stop it with ~/stop_scan first'
        if self.preset_looping or self.target_looping:
            return 'a preset or target loop is running; stop it first'
        return None

    def leave(self) -> None:
        """End each program that runs (SCN_StopScan, PRST_StopPresetLooping,
        GPS_StopTargetLooping), before a new motion command."""
        if self.scanning:
            self._client.request('SCN_StopScan')
            self.scanning = False
        if self.preset_looping:
            self._client.request('PRST_StopPresetLooping')
            self.preset_looping = False
        if self.target_looping:
            self._client.request('GPS_StopTargetLooping')
            self.target_looping = False
