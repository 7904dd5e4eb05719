"""~/look_at_geo of the turret node (process) against the simulator (slcan over a pty).

The pose is the turret's own: the base GNSS position, the rover GNSS heading and the
inclinometer, set through the simulator's `gnss` and `inclination` verbs. The base GNSS
gives its altitude above mean sea level, so the node runs with a geoid_height; the
non-level pose checks that the inclinometer enters as REP-103 roll and -pitch.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import Imu, NavSatFix

from gimbal_driver_common.geodesy import GeoPoint
from gimbal_driver_testing.conformance_rig import ConformanceRig
from gimbal_driver_testing.look_at_geo import LookAtGeoSuite, TestPose

GEOID_HEIGHT = 47.25  # m, N for the test site (EGM2008 gives about 47 m near Munich)


class TestTurretLookAtGeo(LookAtGeoSuite):
    __test__ = True
    driver = "canaero_turret"
    pose = TestPose(GeoPoint(48.1372, 11.5756, 566.5), heading=30.0, roll=1.5, pitch=-2.0)
    position_min = (-math.pi, -0.45)  # pitch: the turret's own range is -30..60 deg

    def node_parameters(self) -> list[str]:
        # a generous link watchdog: the far turns at the slow test yaw take 15 s
        return [*super().node_parameters(), f"geoid_height:={GEOID_HEIGHT}",
                "node_timeout:=2.0", "stale_timeout:=2.0"]

    def apply_pose(self, rig: ConformanceRig, pose: TestPose) -> None:
        rig.sim.control("node_silence all off")
        position = pose.position
        # the inclinometer reads aerospace pitch (nose up positive) = -REP-103 pitch
        rig.sim.set_gnss(position.latitude, position.longitude,
                         position.altitude - GEOID_HEIGHT, pose.heading, pose.roll, -pose.pitch)
        node = f"/{self.node_name}"
        rig.ros.wait_for_message(f"{node}/fix", NavSatFix, lambda m: (
            abs(m.latitude - position.latitude) < 1e-6
            and abs(m.longitude - position.longitude) < 1e-6
            and abs(m.altitude + GEOID_HEIGHT - position.altitude) < 1e-2), timeout=30.0)
        yaw = pose.attitude.yaw
        rig.ros.wait_for_message(f"{node}/heading", Imu, lambda m: abs(math.remainder(
            2 * math.atan2(m.orientation.z, m.orientation.w) - yaw, math.tau)) < 1e-4,
            timeout=30.0)
        rig.ros.wait_for_message(f"{node}/inclination", Vector3Stamped, lambda m: (
            abs(m.vector.x - math.radians(pose.roll)) < 1e-4
            and abs(m.vector.y + math.radians(pose.pitch)) < 1e-3), timeout=30.0)

    def remove_pose(self, rig: ConformanceRig) -> str:
        # a node started while the GNSS nodes are silent has never had a fix or a heading
        rig.sim.control("node_silence base_gnss on")
        rig.sim.control("node_silence rover_gnss on")
        rig.start_node(f"geoid_height:={GEOID_HEIGHT}")
        return "no base GNSS position received"
