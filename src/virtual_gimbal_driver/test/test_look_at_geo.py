"""~/look_at_geo of the reference driver (node process) against its simulator.

The virtual gimbal cannot know where it stands: the pose comes from the site_position and
site_orientation parameters, set at run time, with a non-level orientation.
"""

from __future__ import annotations

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_common.geodesy import GeoPoint
from gimbal_driver_testing.look_at_geo import LookAtGeoSuite, TestPose


class TestVirtualGimbalLookAtGeo(LookAtGeoSuite):
    __test__ = True
    driver = 'virtual_gimbal'
    pose = TestPose(GeoPoint(52.5163, 13.3777, 74.0), heading=300.0, roll=2.0, pitch=-3.0)
