"""The geodesy of ~/look_at_geo in-process: WGS84 -> ENU -> base frame, and the pose rules.

The ENU offsets are checked against geographiclib (an independent implementation: the
geodesic problem on the WGS84 ellipsoid, Karney's algorithms), the rotations against
directions worked out by hand, and :func:`resolve_pose` against every refusal it makes.
"""

from __future__ import annotations

import math

import numpy as np
import pymap3d
import pytest
from geographiclib.geodesic import Geodesic

from gimbal_driver_common.errors import InvalidRequest
from gimbal_driver_common.geodesy import (
    SITE_ORIENTATION,
    SITE_POSITION,
    Attitude,
    DevicePose,
    GeoPoint,
    OrientationFix,
    PoseLimits,
    PoseUnavailable,
    PositionFix,
    base_frame_point,
    bearing_elevation,
    describe_target,
    enu_offset,
    resolve_pose,
)

MUNICH = GeoPoint(48.1372, 11.5756, 566.5)


def pose_at(point: GeoPoint, attitude: Attitude):
    return resolve_pose(None, point, attitude)


@pytest.mark.parametrize('azimuth', [0.0, 45.0, 137.5, 200.0, 333.0])
@pytest.mark.parametrize('distance', [50.0, 1000.0, 20000.0])
def test_enu_bearing_and_distance_agree_with_geographiclib(azimuth: float,
                                                           distance: float) -> None:
    line = Geodesic.WGS84.Direct(MUNICH.latitude, MUNICH.longitude, azimuth, distance)
    target = GeoPoint(line['lat2'], line['lon2'], MUNICH.altitude)
    bearing, elevation, _ = bearing_elevation(enu_offset(target, MUNICH))
    inverse = Geodesic.WGS84.Inverse(MUNICH.latitude, MUNICH.longitude, target.latitude,
                                     target.longitude)
    difference = math.remainder(math.degrees(bearing) - inverse['azi1'], 360.0)
    assert difference == pytest.approx(0.0, abs=1e-4)  # deg, 0.36 arcsec
    # same ellipsoidal height: the target sinks below the tangent plane by about d^2/2R
    assert math.degrees(elevation) == pytest.approx(
        -math.degrees(distance / (2 * 6.371e6)), abs=0.01)
    east, north, _ = enu_offset(target, MUNICH)
    assert math.hypot(east, north) == pytest.approx(distance, rel=1e-4)


def test_enu_offset_inverts_pymap3d_enu2geodetic() -> None:
    latitude, longitude, altitude = pymap3d.enu2geodetic(
        700.0, -300.0, 120.0, MUNICH.latitude, MUNICH.longitude, MUNICH.altitude)
    offset = enu_offset(GeoPoint(latitude, longitude, altitude), MUNICH)
    assert offset == pytest.approx([700.0, -300.0, 120.0], abs=1e-6)


def test_a_level_base_facing_east_sees_north_on_its_left() -> None:
    pose = pose_at(MUNICH, Attitude.from_heading(math.radians(90.0)))
    north = GeoPoint(*pymap3d.enu2geodetic(0.0, 1000.0, 0.0, *(
        MUNICH.latitude, MUNICH.longitude, MUNICH.altitude)))
    x, y, z = base_frame_point(north, pose)
    assert (x, y, z) == pytest.approx((0.0, 1000.0, 0.0), abs=1e-6)  # REP-103: +y is left


def test_heading_and_yaw_are_the_same_angle_counted_two_ways() -> None:
    attitude = Attitude.from_heading(math.radians(30.0))
    assert math.degrees(attitude.yaw) == pytest.approx(60.0)
    assert math.degrees(attitude.heading) == pytest.approx(30.0)
    assert math.degrees(Attitude(yaw=math.radians(-100.0)).heading) == pytest.approx(190.0)


def test_pitch_and_roll_tilt_the_base_frame_as_rep103_says() -> None:
    # REP-103: pitch about +y (left): positive puts the nose down, so a target ahead on
    # the horizon shows above the base's x axis; roll about +x: positive lowers the right
    # side, so a target on the right horizon shows above the y axis.
    ahead = np.array([1000.0, 0.0, 0.0])
    pitched = Attitude(pitch=math.radians(10.0)).matrix().T @ ahead
    assert math.degrees(math.atan2(pitched[2], pitched[0])) == pytest.approx(10.0)
    right = np.array([0.0, -1000.0, 0.0])
    rolled = Attitude(roll=math.radians(5.0)).matrix().T @ right
    assert math.degrees(math.atan2(rolled[2], -rolled[1])) == pytest.approx(5.0)


def test_attitude_applies_yaw_then_pitch_then_roll() -> None:
    attitude = Attitude(roll=0.1, pitch=-0.2, yaw=1.0)
    c, s = math.cos, math.sin
    rz = np.array([[c(1.0), -s(1.0), 0], [s(1.0), c(1.0), 0], [0, 0, 1]])
    ry = np.array([[c(-0.2), 0, s(-0.2)], [0, 1, 0], [-s(-0.2), 0, c(-0.2)]])
    rx = np.array([[1, 0, 0], [0, c(0.1), -s(0.1)], [0, s(0.1), c(0.1)]])
    assert attitude.matrix() == pytest.approx(rz @ ry @ rx)


def test_describe_target_gives_bearing_elevation_and_distance() -> None:
    pose = pose_at(MUNICH, Attitude())
    target = GeoPoint(*pymap3d.enu2geodetic(1000.0, 1000.0, 0.0, MUNICH.latitude,
                                            MUNICH.longitude, MUNICH.altitude))
    text = describe_target(target, pose)
    assert 'bearing 45.00 deg' in text and 'elevation 0.00 deg' in text and '1414.2 m' in text


@pytest.mark.parametrize('point, name', [
    (GeoPoint(91.0, 0.0, 0.0), 'latitude'), (GeoPoint(0.0, -181.0, 0.0), 'longitude'),
    (GeoPoint(0.0, 0.0, math.nan), 'altitude'), (GeoPoint(0.0, 0.0, 2e5), 'altitude')])
def test_points_out_of_range_are_refused_by_name(point: GeoPoint, name: str) -> None:
    with pytest.raises(InvalidRequest, match=f'target {name}'):
        point.checked('target')


def fresh_device(now: float, position_error: float | None = 1.0,
                 heading_error: float | None = 0.001, age: float = 0.5) -> DevicePose:
    return DevicePose(
        PositionFix(MUNICH, 'base GNSS', stamp=now - age, error=position_error),
        OrientationFix(Attitude.from_heading(1.0), 'rover GNSS heading', stamp=now - age,
                       heading_error=heading_error))


def test_a_fresh_accurate_device_pose_is_used_as_it_is() -> None:
    pose = resolve_pose(fresh_device(1000.0), now=1000.0)
    assert pose.from_device and pose.position.point == MUNICH
    assert pose.orientation.attitude.heading == pytest.approx(1.0)


def test_site_parameters_override_the_device_part_by_part() -> None:
    site = GeoPoint(1.0, 2.0, 3.0)
    pose = resolve_pose(fresh_device(1000.0), site_position=site, now=1000.0)
    assert pose.position.point == site and pose.position.source == SITE_POSITION
    assert pose.orientation.source == 'rover GNSS heading' and not pose.from_device
    pose = resolve_pose(fresh_device(1000.0), site_orientation=Attitude(yaw=0.3), now=1000.0)
    assert pose.orientation.source == SITE_ORIENTATION and pose.position.point == MUNICH


def test_no_pose_names_both_missing_parts_and_the_parameters() -> None:
    with pytest.raises(PoseUnavailable) as refused:
        resolve_pose(None)
    text = str(refused.value)
    assert 'no position (the device cannot know where it stands)' in text
    assert 'no orientation' in text and 'site_position' in text and 'site_orientation' in text


def test_a_missing_part_carries_the_device_reason() -> None:
    device = DevicePose(orientation=OrientationFix(Attitude(), 'heading', stamp=10.0),
                        missing={'position': 'no GNSS fix (GPS_PositionReady 0)'})
    with pytest.raises(PoseUnavailable, match=r'no position \(no GNSS fix \(GPS_PositionReady'):
        resolve_pose(device, now=10.0)
    assert resolve_pose(device, site_position=MUNICH, now=10.0).position.point == MUNICH


def test_an_old_fix_is_refused_with_its_age() -> None:
    with pytest.raises(PoseUnavailable, match=r'position from base GNSS is 7.0 s old '
                                              r'\(pose_max_age 5 s\)'):
        resolve_pose(fresh_device(1000.0, age=7.0), now=1000.0)
    pose = resolve_pose(fresh_device(1000.0, age=7.0), limits=PoseLimits(max_age=10.0),
                        now=1000.0)
    assert pose.from_device


def test_a_poor_fix_or_heading_is_refused_with_the_limit() -> None:
    with pytest.raises(PoseUnavailable, match=r'accuracy 25.0 m .* > pose_max_position_error 10'):
        resolve_pose(fresh_device(1000.0, position_error=25.0), now=1000.0)
    with pytest.raises(PoseUnavailable, match=r'heading accuracy 5.73 deg .* > '
                                              r'pose_max_heading_error 2.00 deg'):
        resolve_pose(fresh_device(1000.0, heading_error=0.1), now=1000.0)
    # no reported accuracy is not a poor one; a surveyed (stamp None) fix never ages
    device = DevicePose(PositionFix(MUNICH, 'inserted'), OrientationFix(Attitude(), 'inserted'))
    assert resolve_pose(device, now=1e12).from_device
