"""The conformance suite against kessler_kos_driver_node (a process) and the kOS simulator
over TCP: the registry's handle (``KesslerSimHandle``) in the test process, so the suite
sees every message the device received."""

from __future__ import annotations

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_common.testing.conformance import DriverConformance


class TestKesslerKosConformance(DriverConformance):
    __test__ = True
    driver = 'kessler_kos'
    # rad (2*pi per motor rotation, the spec's joint_scales), in the spec's joint order,
    # inside the simulator's calibrated ranges: pan 0..100 rot, tilt 0..-40 rot, slider 0..200
    joints = ('pan', 'tilt', 'slider')
    small_move = {'pan': 20.0, 'tilt': -20.0}
    far_move = ('pan', 600.0, 5.0)
    jog = ('pan', 20.0)
    tolerance = 0.011
    preset_index = 4
    scan = dict(pattern='sector', pan_min=10.0, pan_max=30.0, speed=10.0)
