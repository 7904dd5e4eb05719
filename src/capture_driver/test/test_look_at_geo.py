"""~/look_at_geo of capture_driver_node (process) against the Capture simulator over TCP.

The pose is the pedestal's own inserted position and heading (the override flag set; the
simulator's `inserted` verb), and the driver gives the target to the pedestal's own
pointing (GPS_SetTargetLLA + GPS_GoToTarget) after checking its own solution against the
limits. With site_position the driver moves itself (the pedestal would aim from another
position); with no inserted position and no GPS fix the goal is refused.
"""

from __future__ import annotations

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_common.geodesy import GeoPoint
from gimbal_driver_testing.conformance_rig import ConformanceRig
from gimbal_driver_testing.look_at_geo import LookAtGeoSuite, TestPose


class TestCaptureLookAtGeo(LookAtGeoSuite):
    __test__ = True
    driver = 'capture'
    pose = TestPose(GeoPoint(32.1040, 34.8915, 65.43), heading=30.0)  # level: heading only

    def node_parameters(self) -> list[str]:
        """The suite's, with every answer of the simulator waited for (nothing here is
        meant to go unanswered): the simulator shares the test process with the ROS
        client, and on a loaded machine a GPS_PositionReady read answered after the
        default 0.5 s made a refusal name the timeout instead of the missing fix, and its
        back-off the next goal's (issue 45, docs/testing.md)."""
        return [*super().node_parameters(), 'request_timeout:=5.0']

    def apply_pose(self, rig: ConformanceRig, pose: TestPose) -> None:
        self.set_site(rig, None)
        position = pose.position
        rig.sim.set_inserted(position.latitude, position.longitude, position.altitude,
                             pose.heading)

    def remove_pose(self, rig: ConformanceRig) -> str:
        self.set_site(rig, None)
        rig.sim.set_inserted(None)
        rig.sim.control('gps nofix')
        return 'no position (no GPS fix (GPS_PositionReady 0))'

    @pytest.mark.ros
    def test_the_pedestal_points_itself_at_the_target(self, rig: ConformanceRig) -> None:
        mark = rig.sim.mark()
        self.reach(rig, self.pose, self.pose.place(-30.0, 10.0, 2000.0))
        assert {'GPS_SetTargetLLA', 'GPS_GoToTarget'} <= set(rig.sim.requests()[mark:])

    @pytest.mark.ros
    def test_with_site_position_the_driver_moves_itself(self, rig: ConformanceRig) -> None:
        rig.sim.set_gps(self.pose.position.latitude, self.pose.position.longitude, 0.0,
                        self.pose.heading)
        rig.sim.set_inserted(None)
        pose = self.pose
        self.set_site(rig, pose)  # both parts: the GPS heading is overridden as well
        mark = rig.sim.mark()
        result, _, _ = self.look_at_geo(rig, pose.place(25.0, 5.0, 1500.0))
        assert result.success, result.message
        assert 'by a driver move' in result.message
        assert 'GPS_GoToTarget' not in rig.sim.requests()[mark:]

    @pytest.mark.ros
    def test_gps_without_an_altitude_is_refused_naming_it(self, rig: ConformanceRig) -> None:
        self.set_site(rig, None)
        rig.sim.set_inserted(None)
        rig.sim.set_gps(self.pose.position.latitude, self.pose.position.longitude, 0.0, 10.0)
        self.refused(rig, self.pose.place(0.0, 0.0, 1000.0), 'the GPS gives no altitude')
