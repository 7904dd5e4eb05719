"""The ~/look_at_geo checks every driver runs against its simulator (node as a process).

A driver's test subclasses :class:`LookAtGeoSuite` (``__test__ = True``, ``driver`` = its
registry name) and says how the device gets its pose: by default the ``site_position`` /
``site_orientation`` parameters, set at run time (a device that cannot know its pose);
a device with GNSS overrides :meth:`LookAtGeoSuite.apply_pose` (its simulator's control
verbs, through the registry's sim handle) and :meth:`LookAtGeoSuite.remove_pose`.

Targets are built by construction with the same geodesy (``pymap3d.enu2geodetic`` from a
bearing relative to the device, an elevation and a distance), and the expected joint
positions come from the package's URDF chain; one test checks the angles against an
independent computation instead (geographiclib's inverse geodesic for the azimuth, a
spherical-earth drop for the elevation), to 0.1 deg. "Nothing sent" is the simulator's
receive side: no request that moves or changes the device.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import pymap3d
import pytest
from geographiclib.geodesic import Geodesic
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from gimbal_driver_common.geodesy import Attitude, GeoPoint, base_frame_point, resolve_pose
from gimbal_driver_common.kinematics import AimingChain
from gimbal_driver_testing.conformance_rig import (
    ConformanceRig,
    GoalStatus,
    RegisteredDriver,
)
from gimbal_driver_testing.look_at import installed_description
from gimbal_driver_testing.ros import joint_positions
from gimbal_msgs.action import LookAtGeo

#: the independent check's tolerance (deg)
ANGLE_TOLERANCE_DEG = 0.1
#: mean earth radius for the independent elevation (m): the drop over a few km differs
#: from the ellipsoid's by far less than the tolerance
EARTH_RADIUS_M = 6371000.0


@dataclass(frozen=True)
class TestPose:
    """Where the suite puts the device: a place and the base frame's attitude (heading
    in deg clockwise from north, roll and pitch in deg, REP-103 signs)."""

    __test__ = False  # not a test class (pytest collects Test* names)

    position: GeoPoint
    heading: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0

    @property
    def attitude(self) -> Attitude:
        return Attitude.from_heading(math.radians(self.heading), math.radians(self.roll),
                                     math.radians(self.pitch))

    def place(self, relative_bearing: float, elevation: float, distance: float) -> GeoPoint:
        """The place seen ``relative_bearing`` deg left (counter-clockwise) of the base's
        heading, ``elevation`` deg above the local horizontal, ``distance`` m away."""
        bearing = math.radians(self.heading - relative_bearing)
        horizontal = distance * math.cos(math.radians(elevation))
        latitude, longitude, altitude = pymap3d.enu2geodetic(
            horizontal * math.sin(bearing), horizontal * math.cos(bearing),
            distance * math.sin(math.radians(elevation)), self.position.latitude,
            self.position.longitude, self.position.altitude)
        return GeoPoint(float(latitude), float(longitude), float(altitude))


class LookAtGeoSuite(RegisteredDriver):
    """~/look_at_geo: ahead-right at 1 km, 30 deg up, behind, below the tilt range, no
    pose, and the independent check. The node runs with tilt ``position_min`` -0.8 rad."""

    __test__ = False  # a subclass per driver sets True

    #: the pose of the shared tests (a non-level one where the device reports roll/pitch)
    pose = TestPose(GeoPoint(48.1372, 11.5756, 566.5), heading=30.0)
    #: the pose of the independent check: level (the azimuth is then the pan)
    level_pose = TestPose(GeoPoint(-33.8568, 151.2153, 42.0), heading=200.0)
    #: joint positions within this of the expected ones count as reached (rad)
    tolerance = 0.02
    #: the node's lower limits; the tilt's (-0.8 rad) puts a target 60 deg below the
    #: horizon beyond it
    position_min: tuple[float, ...] = (-math.pi, -0.8)

    # ------------------------------------------------------------------ hooks
    def node_parameters(self) -> list[str]:
        """Test-speed parameters; ``position_min`` puts the tilt limit where the suite
        needs it, and a goal tolerance well inside the independent check's 0.1 deg (the
        result reports where the joints ended)."""
        return ['reconnect_period:=0.3', f'position_min:={list(self.position_min)}',
                'goal_tolerance:=0.001']

    def apply_pose(self, rig: ConformanceRig, pose: TestPose) -> None:
        """Give the node ``pose`` (default: the site parameters, set at run time)."""
        self.set_site(rig, pose)

    def remove_pose(self, rig: ConformanceRig) -> str:
        """Leave the node with no pose; return what its refusal must name."""
        self.set_site(rig, None)
        return 'no position (the device cannot know where it stands)'

    def set_site(self, rig: ConformanceRig, pose: TestPose | None) -> None:
        position = orientation = []
        if pose is not None:
            attitude = pose.attitude
            position = [pose.position.latitude, pose.position.longitude, pose.position.altitude]
            orientation = [attitude.roll, attitude.pitch, attitude.yaw]
        for name, value in (('site_position', position), ('site_orientation', orientation)):
            # typed explicitly: an empty list would otherwise go out as a byte array
            request = SetParameters.Request(parameters=[
                Parameter(name, Parameter.Type.DOUBLE_ARRAY, value).to_parameter_msg()])
            reply = rig.ros.call(SetParameters, f'/{self.node_name}/set_parameters',
                                 request).results[0]
            assert reply.successful, reply.reason

    # ---------------------------------------------------------------- fixtures
    @pytest.fixture(scope='class')
    @classmethod
    def geo_rig(cls, tmp_path_factory) -> Iterator[ConformanceRig]:
        rig = ConformanceRig(cls(), tmp_path_factory.mktemp(f'{cls.driver}-look_at_geo'))
        try:
            yield rig
        finally:
            rig.close()

    @pytest.fixture
    def rig(self, geo_rig: ConformanceRig) -> ConformanceRig:
        geo_rig.shared_node()
        return geo_rig

    # ----------------------------------------------------------------- helpers
    def chain(self) -> AimingChain:
        return AimingChain.from_file(installed_description(self.package))

    def look_at_geo(self, rig: ConformanceRig, target: GeoPoint, speed: float = 0.0):
        goal = LookAtGeo.Goal(latitude=target.latitude, longitude=target.longitude,
                              altitude=target.altitude, speed=speed)
        return rig.ros.run_action(LookAtGeo, f'/{self.node_name}/look_at_geo', goal,
                                  timeout=90.0)

    def expected(self, rig: ConformanceRig, pose: TestPose, target: GeoPoint) -> list[float]:
        """Pan and tilt by construction: the target in the base frame, solved on the URDF."""
        chain = self.chain()
        state = joint_positions(rig.ros.wait_for_message('joint_states', JointState))
        point = base_frame_point(target, resolve_pose(None, pose.position, pose.attitude))
        angles = chain.solve(tuple(point), state)
        return [angles[chain.pan_joint], angles[chain.tilt_joint]]  # pan: compared mod 2 pi

    def reach(self, rig: ConformanceRig, pose: TestPose, target: GeoPoint) -> list[float]:
        """look_at_geo ``target``: success, the expected joints, joint_states there."""
        self.apply_pose(rig, pose)
        expected = self.expected(rig, pose, target)
        result, status, feedback = self.look_at_geo(rig, target)
        assert result.success, result.message
        assert status == GoalStatus.STATUS_SUCCEEDED
        chain = self.chain()
        assert list(result.joint_names) == [chain.pan_joint, chain.tilt_joint]
        assert _turns_apart(result.positions, expected) == pytest.approx(
            [0.0, 0.0], abs=self.tolerance), (list(result.positions), expected)
        assert feedback and all(len(f.positions) == 2 for f in feedback)
        rig.ros.wait_for_message(
            'joint_states', JointState,
            lambda m: _turns_apart([joint_positions(m).get(j, math.inf) for j in
                                    result.joint_names], expected) == pytest.approx(
                [0.0, 0.0], abs=self.tolerance), timeout=30.0)
        return list(result.positions)

    def refused(self, rig: ConformanceRig, target: GeoPoint, expected: str) -> None:
        """look_at_geo must answer success=false naming ``expected``, and the device must
        receive nothing that moves or changes it."""
        mark = rig.sim.mark()
        result, status, _ = self.look_at_geo(rig, target)
        assert not result.success and status == GoalStatus.STATUS_ABORTED
        assert 'nothing sent' in result.message and expected in result.message, result.message
        assert rig.sim.changes_since(mark) == []

    # ------------------------------------------------------------------- tests
    @pytest.mark.ros
    def test_target_1_km_north_east_at_the_same_height(self, rig: ConformanceRig) -> None:
        target = self.pose.place(self.pose.heading - 45.0, 0.0, 1000.0)  # bearing 45 deg
        self.reach(rig, self.pose, target)

    @pytest.mark.ros
    def test_target_30_deg_above_the_horizon(self, rig: ConformanceRig) -> None:
        _, tilt = self.reach(rig, self.pose, self.pose.place(20.0, 30.0, 1000.0))
        if self.pose.roll == self.pose.pitch == 0.0:  # level: the tilt is the elevation
            assert math.degrees(tilt) == pytest.approx(30.0, abs=0.5)

    @pytest.mark.ros
    def test_target_behind_the_device(self, rig: ConformanceRig) -> None:
        target = self.pose.place(160.0, 5.0, 800.0)
        x, _, _ = base_frame_point(target, resolve_pose(None, self.pose.position,
                                                        self.pose.attitude))
        assert x < 0.0  # behind the base frame
        self.reach(rig, self.pose, target)

    @pytest.mark.ros
    def test_target_below_the_tilt_range_is_refused_and_sends_nothing(
            self, rig: ConformanceRig) -> None:
        self.apply_pose(rig, self.pose)
        self.refused(rig, self.pose.place(0.0, -60.0, 1000.0), 'position_min')

    @pytest.mark.ros
    def test_no_pose_is_refused_and_sends_nothing(self, rig: ConformanceRig) -> None:
        expected = self.remove_pose(rig)
        self.refused(rig, self.pose.place(0.0, 0.0, 1000.0), expected)

    @pytest.mark.ros
    def test_angles_agree_with_an_independent_geodesic(self, rig: ConformanceRig) -> None:
        pose = self.level_pose
        target = pose.place(-40.0, 0.0, 3000.0)
        target = replace(target, altitude=pose.position.altitude + 150.0)
        pan, tilt = self.reach(rig, pose, target)
        inverse = Geodesic.WGS84.Inverse(pose.position.latitude, pose.position.longitude,
                                         target.latitude, target.longitude)
        # REP-103 pan counts counter-clockwise, the azimuth clockwise, both from the heading
        expected_pan = math.remainder(pose.heading - inverse['azi1'], 360.0)
        distance = inverse['s12']
        drop = distance * distance / (2.0 * EARTH_RADIUS_M)
        expected_tilt = math.degrees(math.atan2(150.0 - drop, distance))
        reached = (math.degrees(pan), math.degrees(tilt))
        assert math.remainder(reached[0] - expected_pan, 360.0) == pytest.approx(
            0.0, abs=ANGLE_TOLERANCE_DEG), (reached, expected_pan)
        assert reached[1] == pytest.approx(expected_tilt, abs=ANGLE_TOLERANCE_DEG), (
            reached, expected_tilt)


def _turns_apart(actual, expected) -> list[float]:
    """Pan and tilt differences, the pan taken modulo whole turns."""
    return [math.remainder(actual[0] - expected[0], 2 * math.pi), actual[1] - expected[1]]
