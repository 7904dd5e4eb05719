"""~/look_at_geo of kessler_kos_driver_node (process) against the simulator (TCP).

A kOS rig cannot know where it stands: the pose comes from the site_position and
site_orientation parameters, set at run time. The chain is slider -> pan -> tilt; the
slider is held. The registry's joints are [pan, tilt, slider]; the simulator's pan and
tilt motors get a calibrated range on both sides of their begin mark (-50..50 rotations),
so the rig can turn either way and look below the horizon.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_common.geodesy import GeoPoint
from gimbal_driver_common.sim_handle import SimHandle
from gimbal_driver_testing.look_at_geo import LookAtGeoSuite, TestPose


class TestKesslerLookAtGeo(LookAtGeoSuite):
    __test__ = True
    driver = 'kessler_kos'
    pose = TestPose(GeoPoint(51.5007, -0.1246, 60.0), heading=75.0, pitch=1.0)
    position_min = (-math.pi, -0.8, -1000.0)  # pan, tilt, slider (m)

    def start_simulator(self, workdir: Path, domain: int) -> SimHandle:
        handle = super().start_simulator(workdir, domain)
        device = handle.sim.device
        with device.lock:
            for motor in device.motors.values():
                if motor.role in ('pan', 'tilt'):
                    motor.begin, motor.end = -50.0, 50.0
        return handle
