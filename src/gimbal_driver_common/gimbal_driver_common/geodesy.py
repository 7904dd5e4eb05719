"""Where a place on Earth lies in the device's base frame, and where the device stands (no ROS).

``~/look_at_geo`` turns a WGS84 target (latitude, longitude, altitude above the ellipsoid,
as sensor_msgs/NavSatFix) into a point in the device's base frame and then aims at it like
``~/look_at``. The chain of frames:

1. WGS84 geodetic -> ECEF -> the local ENU (east, north, up) frame at the device, by
   ``pymap3d`` (``geodetic2ecef``, ``ecef2enu``; ellipsoid WGS84), not hand-written formulas;
2. ENU -> the base frame by the base frame's attitude in ENU: REP-103 roll, pitch, yaw
   (fixed axes, R = Rz Ry Rx, yaw counter-clockwise from east), so a point p_enu is
   ``R.T @ p_enu`` in the base frame. A compass heading h (clockwise from north) is the
   yaw pi/2 - h.

Where the device stands comes from a :class:`DevicePose` (what a device adapter's
``Geolocation`` capability reports: position and orientation, each with its source, the
time it was measured and its accuracy, or why it has none) and from the ``site_position``
/ ``site_orientation`` parameters, which override the device's values part by part.
:func:`resolve_pose` combines them and refuses, naming what is missing, too old or too
poor, so nothing is sent on a pose the driver cannot trust.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from gimbal_driver_common.errors import DeviceRefused, InvalidRequest
from gimbal_driver_common.kinematics import rotation_rpy
from gimbal_driver_common.orientation import wrap_angle

#: the sources the site parameters give (a pose from them is the user's, not the device's)
SITE_POSITION = 'site_position'
SITE_ORIENTATION = 'site_orientation'
#: altitudes accepted for a target or a site (m above the ellipsoid): the deepest geoid
#: low (about -106 m) below the lowest land, up to well above what a gimbal aims at
ALTITUDE_RANGE = (-12000.0, 100000.0)


class PoseUnavailable(DeviceRefused):
    """The device's position or orientation is unknown, too old or too poor; nothing sent."""


@dataclass(frozen=True)
class GeoPoint:
    """A place: latitude and longitude in degrees (WGS84), altitude in m above the ellipsoid."""

    latitude: float
    longitude: float
    altitude: float

    def checked(self, what: str) -> GeoPoint:
        """This point, or InvalidRequest naming ``what`` and the value out of range."""
        for name, value, low, high in (
                ('latitude', self.latitude, -90.0, 90.0),
                ('longitude', self.longitude, -180.0, 180.0),
                ('altitude', self.altitude, *ALTITUDE_RANGE)):
            if not math.isfinite(value) or not low <= value <= high:
                raise InvalidRequest(f'{what} {name} {value} is outside [{low:g}, {high:g}]')
        return self

    def __str__(self) -> str:
        return f'{self.latitude:.7f} deg, {self.longitude:.7f} deg, {self.altitude:.2f} m'


@dataclass(frozen=True)
class Attitude:
    """Orientation of the device's base frame in the local ENU frame (REP-103, rad):
    roll about x, pitch about y, yaw about z counter-clockwise from east (R = Rz Ry Rx)."""

    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0

    @classmethod
    def from_heading(cls, heading: float, roll: float = 0.0, pitch: float = 0.0) -> Attitude:
        """From a compass heading of the base frame's +x axis (rad, clockwise from north)."""
        return cls(roll, pitch, wrap_angle(math.pi / 2.0 - heading))

    @property
    def heading(self) -> float:
        """Compass heading of the base frame's +x axis (rad, clockwise from north, [0, 2 pi))."""
        return (math.pi / 2.0 - self.yaw) % (2.0 * math.pi)

    def matrix(self) -> np.ndarray:
        """Rotation base -> ENU (its columns are the base axes in ENU)."""
        return rotation_rpy(self.roll, self.pitch, self.yaw)

    def __str__(self) -> str:
        return (f'roll {math.degrees(self.roll):.2f} deg, pitch {math.degrees(self.pitch):.2f} '
                f'deg, heading {math.degrees(self.heading):.2f} deg')


@dataclass(frozen=True)
class PositionFix:
    """Where the device stands and how much to trust it."""

    point: GeoPoint
    source: str                 # e.g. 'base GNSS', 'GPS inserted position', 'site_position'
    stamp: float | None = None  # wall time (time.time()) of the fix; None: it does not age
    error: float | None = None  # m, 1-sigma horizontal accuracy; None: not reported


@dataclass(frozen=True)
class OrientationFix:
    """Which way the device's base frame faces and how much to trust it."""

    attitude: Attitude
    source: str
    stamp: float | None = None          # as PositionFix.stamp
    heading_error: float | None = None  # rad, 1-sigma; None: not reported


@dataclass(frozen=True)
class DevicePose:
    """What a device knows of its own pose; ``missing`` says why a part is None
    (keys ``position`` and ``orientation``)."""

    position: PositionFix | None = None
    orientation: OrientationFix | None = None
    missing: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class PoseLimits:
    """When a device's fix is too old or too poor to aim with (the ``pose_max_*`` parameters)."""

    max_age: float = 5.0                           # s
    max_position_error: float = 10.0               # m, 1 sigma
    max_heading_error: float = math.radians(2.0)   # rad, 1 sigma


@dataclass(frozen=True)
class GeoPose:
    """The pose look_at_geo aims from: a trusted position and orientation."""

    position: PositionFix
    orientation: OrientationFix

    @property
    def from_device(self) -> bool:
        """Both parts come from the device (no site parameter overrides them)."""
        return (self.position.source != SITE_POSITION
                and self.orientation.source != SITE_ORIENTATION)

    def __str__(self) -> str:
        return (f'at {self.position.point} ({self.position.source}), '
                f'{self.orientation.attitude} ({self.orientation.source})')


def _untrusted(part: str, source: str, stamp: float | None, error: float | None,
               max_error: float, error_text: str, limits: PoseLimits, now: float) -> str | None:
    """Why a device-reported part is too old or too poor, or None."""
    if stamp is not None and now - stamp > limits.max_age:
        return (f'{part} from {source} is {now - stamp:.1f} s old '
                f'(pose_max_age {limits.max_age:g} s)')
    if error is not None and not error <= max_error:
        return f'{part} from {source} is too poor: {error_text}'
    return None


def resolve_pose(device: DevicePose | None, site_position: GeoPoint | None = None,
                 site_orientation: Attitude | None = None,
                 limits: PoseLimits | None = None, now: float | None = None) -> GeoPose:
    """The pose to aim from: each site parameter that is set overrides the device's part.

    ``device`` is None for a device that cannot know its pose. Raises PoseUnavailable
    naming every part that is missing, too old (older than ``limits.max_age``) or too poor
    (an accuracy worse than the limit); a site parameter is trusted as given.
    """
    limits = limits or PoseLimits()
    now = time.time() if now is None else now
    device = device or DevicePose(missing={
        'position': 'the device cannot know where it stands',
        'orientation': 'the device cannot know which way it faces'})
    problems: list[str | None] = []  # None: a part that passed its check
    position = (PositionFix(site_position, SITE_POSITION) if site_position is not None
                else device.position)
    if position is None:
        why = device.missing.get('position', 'the device reports none')
        problems.append(f'no position ({why}): set site_position [latitude deg, longitude deg,'
                        ' altitude m]')
    elif position.source != SITE_POSITION:
        error = position.error
        problems.append(_untrusted(
            'position', position.source, position.stamp, error, limits.max_position_error,
            f'accuracy {error} m (1 sigma) > pose_max_position_error '
            f'{limits.max_position_error:g} m', limits, now))
    orientation = (OrientationFix(site_orientation, SITE_ORIENTATION)
                   if site_orientation is not None else device.orientation)
    if orientation is None:
        why = device.missing.get('orientation', 'the device reports none')
        problems.append(f'no orientation ({why}): set site_orientation [roll, pitch, yaw rad '
                        'of the base frame in ENU]')
    elif orientation.source != SITE_ORIENTATION:
        error = orientation.heading_error
        problems.append(_untrusted(
            'orientation', orientation.source, orientation.stamp, error,
            limits.max_heading_error,
            f'heading accuracy {math.degrees(error or 0.0):.2f} deg (1 sigma) > '
            f'pose_max_heading_error {math.degrees(limits.max_heading_error):.2f} deg',
            limits, now))
    reasons = [p for p in problems if p]
    if reasons:
        raise PoseUnavailable('device pose unknown: ' + '; '.join(reasons))
    assert position is not None and orientation is not None
    return GeoPose(position, orientation)


def enu_offset(target: GeoPoint, origin: GeoPoint) -> np.ndarray:
    """East, north, up (m) of ``target`` in the local ENU frame at ``origin``:
    WGS84 geodetic -> ECEF -> ENU with pymap3d.

    pymap3d is imported here, at the first geo aim: with its dependencies it is 2.7 MB of
    every node's memory (PSS), and most nodes never get a ``~/look_at_geo`` goal."""
    import pymap3d

    x, y, z = pymap3d.geodetic2ecef(target.latitude, target.longitude, target.altitude)
    east, north, up = pymap3d.ecef2enu(x, y, z, origin.latitude, origin.longitude,
                                       origin.altitude)
    return np.array([float(east), float(north), float(up)])


def base_frame_point(target: GeoPoint, pose: GeoPose) -> np.ndarray:
    """``target`` in the device's base frame (m): its ENU offset rotated by the attitude."""
    return pose.orientation.attitude.matrix().T @ enu_offset(target, pose.position.point)


def bearing_elevation(enu: np.ndarray) -> tuple[float, float, float]:
    """(bearing clockwise from north, elevation above the local horizontal, both rad;
    distance m) of an ENU offset, for messages and checks."""
    east, north, up = (float(v) for v in enu)
    horizontal = math.hypot(east, north)
    return (math.atan2(east, north) % (2.0 * math.pi), math.atan2(up, horizontal),
            math.sqrt(horizontal * horizontal + up * up))


def describe_target(target: GeoPoint, pose: GeoPose) -> str:
    """The target as a person checks it: where it is and how it is seen from the device."""
    bearing, elevation, distance = bearing_elevation(enu_offset(target, pose.position.point))
    return (f'place {target} (bearing {math.degrees(bearing):.2f} deg, elevation '
            f'{math.degrees(elevation):.2f} deg, {distance:.1f} m from the device)')
