"""~/look_at_geo of ucamera_driver_node (process) against the simulator (UCSP over a pty).

Pan and tilt turn relative to the vehicle body, so the pose is the vehicle's: its position
from the gimbal's System Position Report (the simulator's `gnss` verb moves it) and its
attitude from ~/ext/imu, which the test publishes with a non-zero roll, pitch and yaw and
which the node forwards to the gimbal (Send Vehicle Angles) and aims with.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip("gimbal_msgs", reason="needs the colcon-built workspace (make build)")

from sensor_msgs.msg import Imu, NavSatFix

from gimbal_driver_common.geodesy import GeoPoint
from gimbal_driver_common.orientation import quaternion_from_euler
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance_rig import ConformanceRig
from gimbal_driver_testing.look_at_geo import LookAtGeoSuite, TestPose
from ucamera_driver.device_functions import enu_flu_to_ned_frd


class TestUCameraLookAtGeo(LookAtGeoSuite):
    __test__ = True
    driver = "ucamera"
    pose = TestPose(GeoPoint(40.4168, -3.7038, 700.0), heading=250.0, roll=8.0, pitch=-5.0)

    def apply_pose(self, rig: ConformanceRig, pose: TestPose) -> None:
        position, attitude = pose.position, pose.attitude
        rig.sim.set_gnss(position.latitude, position.longitude, position.altitude)
        rig.ros.wait_for_message(f"/{self.node_name}/fix", NavSatFix, lambda m: (
            abs(m.latitude - position.latitude) < 1e-6
            and abs(m.longitude - position.longitude) < 1e-6
            and abs(m.altitude - position.altitude) < 1e-3), timeout=30.0)
        imu = Imu()
        (imu.orientation.x, imu.orientation.y, imu.orientation.z,
         imu.orientation.w) = quaternion_from_euler(attitude.roll, attitude.pitch, attitude.yaw)
        imu.angular_velocity_covariance[0] = -1.0  # orientation only
        sent = enu_flu_to_ned_frd(attitude.roll, attitude.pitch, attitude.yaw)

        def received() -> bool:
            # publish until the gimbal has the angles (the node forwards at most
            # external_feed_rate, and the first message may precede the subscription match)
            rig.ros.publish(f"/{self.node_name}/ext/imu", imu)
            angles = rig.sim.vehicle_angles()
            return angles is not None and all(
                abs(math.remainder(a - b, math.tau)) < 1e-3
                for a, b in zip(angles, sent, strict=True))

        wait_for(received, 30.0, "the gimbal to receive the vehicle angles")

    def remove_pose(self, rig: ConformanceRig) -> str:
        # a new node has had no ~/ext/imu: the gimbal reports no attitude of its own
        rig.start_node("report_publish_rate:=10.0")
        return "no orientation (the U-Camera reports no vehicle attitude"
