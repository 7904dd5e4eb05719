"""The turret's capability objects (no ROS): preset slot 0, its own remember/restore
position (:class:`TurretPresets`), and where the base stands and faces from its GNSS
nodes (:class:`TurretGeolocation`). Each wraps the :class:`~.device.TurretDevice` it serves.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from gimbal_driver_common.device import DevicePresets, Geolocation
from gimbal_driver_common.errors import InvalidRequest
from gimbal_driver_common.geodesy import Attitude, DevicePose, GeoPoint, OrientationFix, PositionFix

from .readings import si, si_magnitude

if TYPE_CHECKING:
    from .device import TurretDevice


PRESET_DEVICE_INDEX = 0  # the turret's own remember/restore position

class TurretPresets(DevicePresets):
    """Slot 0 is the turret's remember/restore position; the driver remembers where it was."""

    def __init__(self, device: TurretDevice) -> None:
        self.device = device
        self.remembered: dict[str, float] | None = None

    def handles(self, index: int) -> bool:
        return index == PRESET_DEVICE_INDEX

    def set(self, index: int, name: str, positions: dict[str, float] | None) -> str:
        if positions is not None:
            raise InvalidRequest("preset 0 is the turret's remembered position: it can only "
                                 "store the current position (use_current_position=true)")
        self.device.client.remember_position()
        self.remembered = self.device.positions()
        return "preset 0: the turret remembered its current position"

    def goto(self, index: int, speed: float) -> str:
        if speed > 0:
            raise InvalidRequest("preset 0 (turret set-to-saved-position) has no speed; "
                                 "use speed 0")
        self.device.client.restore_position()
        return "moving to preset 0 (the turret's saved position)"

    def target(self, index: int) -> dict[str, float] | None:
        return dict(self.remembered) if self.remembered else None

    def list(self) -> list[tuple[int, str, dict[str, float]]]:
        if self.remembered is None:
            return []
        return [(PRESET_DEVICE_INDEX, "turret saved position", dict(self.remembered))]

    def clear(self, index: int | None) -> str:
        self.remembered = None
        if index is None:
            return "all driver-side presets cleared (the turret keeps its saved position)"
        return ("preset 0 lives in the turret and cannot be erased; the driver forgot its "
                "record of it")


class TurretGeolocation(Geolocation):
    """Where the turret stands and faces: the base GNSS position (7.4: latitude, longitude,
    altitude above mean sea level plus ``geoid_height``, accuracy estimate), the rover
    GNSS heading (7.3.1, accuracy 7.3.2) and the base's inclinometer (7.1.31-32).

    The ICD gives the inclinometer no sign convention; it is read as the aerospace one
    (pitch nose-up positive, roll right side down positive), i.e. REP-103 roll = global
    roll, REP-103 pitch = -global pitch (README, decision 21).
    """

    POSITION_KEYS = ("latitude", "longitude", "altitude_msl")
    ORIENTATION_KEYS = ("rover_heading", "global_roll", "global_pitch")

    def __init__(self, device: TurretDevice) -> None:
        self.device = device

    def _readings(self, keys: Sequence[str], what: str) -> tuple[list[float], float] | str:
        """The SI values of ``keys`` and the oldest one's stamp, or why they cannot be used
        (never received, stale)."""
        client = self.device.client
        samples = [client.latest(key) for key in keys]
        values = [si(s) for s in samples]
        absent = [k for k, v in zip(keys, values, strict=True) if v is None]
        if absent:
            return f"no {what} received ({', '.join(absent)})"
        stale = [k for k in keys if client.is_stale(k)]
        if stale:
            age = max(client.age(k) or 0.0 for k in stale)
            return (f"{what} stale: no {', '.join(stale)} for {age:.1f} s "
                    f"(stale after {client.stale_timeout_for(stale[0]):g} s)")
        return ([v for v in values if v is not None],
                min(s.stamp for s in samples if s is not None))

    def pose(self) -> DevicePose:
        missing: dict[str, str] = {}
        position = orientation = None
        read = self._readings(self.POSITION_KEYS, "base GNSS position")
        geoid_height = self.device.settings.geoid_height
        if isinstance(read, str):
            missing["position"] = read
        elif geoid_height is None:
            missing["position"] = (
                "the base GNSS gives the altitude above mean sea level (ICD 7.4.3): set "
                "geoid_height (the geoid height N at the site, m) to make it a height above "
                "the WGS84 ellipsoid")
        else:
            (latitude, longitude, altitude), stamp = read
            accuracy = self.device.readings.fresh("position_accuracy")
            position = PositionFix(
                GeoPoint(latitude, longitude, altitude + geoid_height), "base GNSS",
                stamp=stamp, error=si_magnitude(accuracy))
        read = self._readings(self.ORIENTATION_KEYS, "rover GNSS heading and inclinometer")
        if isinstance(read, str):
            missing["orientation"] = read
        else:
            (heading, roll, pitch), stamp = read
            accuracy = self.device.readings.fresh("rover_heading_accuracy")
            orientation = OrientationFix(
                Attitude.from_heading(heading, roll, -pitch),
                "rover GNSS heading + inclinometer", stamp=stamp,
                heading_error=si_magnitude(accuracy))
        return DevicePose(position, orientation, missing)
