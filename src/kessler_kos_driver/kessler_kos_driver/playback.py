"""kOS trajectory playback in SI (no ROS): load a move from key frames or Bezier segments,
set it up, start and stop it, and the PlaybackStatus notifications in SI. A part of
:class:`~.device.KosDevice` (its ``playback`` attribute), kept apart so the adapter's core
(conversion, link, motion, refusals) reads in one sitting; the node's playback services
call these through ``controller.call``. It is handed the client, the joint table, the
settings, the callback for the reports and the adapter's SI conversion and idle check
(:class:`JointSide`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout

from .client import KosClient, KosError
from .moves import (
    AxisRange,
    JointMapping,
    Keyframe,
    PlaybackSettings,
    from_keyframes,
    from_segments,
)
from .protocol import (
    PlaybackState,
    PlaybackStatus,
    ProtocolError,
    Trajectory,
    playback_state_name,
)
from .units import Conversion

if TYPE_CHECKING:
    from .device import KosSettings


@dataclass
class PlaybackReport:
    """One PlaybackStatus notification with the motor positions in SI, by joint."""

    status: int
    status_name: str
    elapsed: float
    photo_count: int
    positions: dict[str, float] = field(default_factory=dict)


def _finite_or(value: float, default: float) -> float:
    return value if math.isfinite(value) else default


class JointSide(Protocol):
    """What the playback uses of the adapter (:class:`~.device.KosDevice`)."""

    def conversion(self, joint: str) -> Conversion:
        """The joint's SI conversion at the calibration the device last reported."""

    def to_si(self, joint: str, rotations: float) -> float:
        """A position in rotations as SI."""

    def joint_of(self, address: int) -> str | None:
        """The joint a motor address drives."""

    def require_idle(self) -> None:
        """Refuse while a move plays."""


class KosPlayback:
    """The trajectory playback of :class:`~.device.KosDevice`."""

    def __init__(self, client: KosClient, joints: dict[str, JointMapping],
                 settings: KosSettings, on_playback: Callable[[PlaybackReport], None],
                 adapter: JointSide) -> None:
        self.client = client
        self.joints = joints  # the adapter's table (it changes units in place)
        self.settings = settings
        self.on_playback = on_playback
        self.adapter = adapter

    # ------------------------------------------------------------- playback
    def _ranges(self) -> dict[int, AxisRange]:
        return {a: AxisRange(m.begin_position, m.end_position)
                for a, m in self.client.motors.items() if m.online}

    def load_keyframes(self, frames: list[Keyframe], settings: PlaybackSettings) -> Trajectory:
        """Fit SI key frames to the calibrated ranges, load and confirm the move."""
        self.adapter.require_idle()
        self.client.refresh_motors()
        return self._load(lambda: from_keyframes(frames, self.joints, self._ranges(), settings))

    def load_segments(
        self, segments: dict[str, list[tuple[float, ...]]], settings: PlaybackSettings
    ) -> Trajectory:
        """Load explicit normalised Bezier segments per joint."""
        self.adapter.require_idle()
        self.client.refresh_motors()
        return self._load(lambda: from_segments(segments, self.joints, settings))

    def _load(self, build: Callable[[], Trajectory]) -> Trajectory:
        """Build and load; a refusal names the joints behind the device's motor numbers."""
        try:
            trajectory = build()
            self.client.commands.load_trajectory(trajectory)
        except (ProtocolError, KosError) as exc:
            raise DeviceRefused(f'trajectory not loaded: {exc}; {self._rotations_legend()}'
                                ) from exc
        return trajectory

    def _rotations_legend(self) -> str:
        """What a device figure in rotations means for each joint (refusals quote them)."""
        parts = []
        for name, mapping in self.joints.items():
            units = self.adapter.conversion(name)
            parts.append(f'motor {mapping.address} is joint {name!r}, 1 rotation = '
                         f'{abs(units.per_rotation):.6g} ({units.describe()})')
        return '; '.join(parts)

    def setup_playback(self, delay_return: bool) -> None:
        """SetupPlayback, answered once SetupCompleted arrives."""
        self.adapter.require_idle()
        client = self.client
        marker = len(client.playback.history)
        client.commands.setup_playback(delay_return=delay_return)
        timeout = self.settings.playback_timeout
        if not client.wait_for(
                lambda: PlaybackState.SETUP_COMPLETED in client.playback.history[marker:],
                timeout):
            raise DeviceTimeout(f'no SetupCompleted notification within {timeout:g} s')

    def start_playback(self) -> None:
        self.adapter.require_idle()
        self.client.commands.start_playback()

    def stop_playback(self) -> None:
        self.client.commands.stop_playback()

    def notified(self, note: PlaybackStatus) -> None:
        """A PlaybackStatus notification (reader thread), reported in SI by joint."""
        photos = note.photo_count
        report = PlaybackReport(
            status=int(note.status), status_name=playback_state_name(note.status),
            elapsed=float(_finite_or(note.elapsed_time, 0.0)),
            photo_count=(min(round(photos), 2**32 - 1)
                         if math.isfinite(photos) and photos >= 0 else 0))
        for address, position in sorted(note.positions.items()):
            name = self.adapter.joint_of(address)
            if name is not None:
                report.positions[name] = self.adapter.to_si(name, float(position))
        self.on_playback(report)
