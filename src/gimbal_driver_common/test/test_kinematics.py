"""Aiming a URDF pan/tilt chain at a point: forward kinematics and the solver (no ROS)."""

from __future__ import annotations

import math
import random
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('urdf_parser_py', reason='needs urdfdom-py (make build)')
from gimbal_driver_common.kinematics import (
    AimingChain,
    KinematicsError,
    nearest_in_limits,
    wrap_angle,
)

# the reference driver's chain (test/pan_tilt.urdf: a copy, so this package's tests read
# only its own files)
VIRTUAL_GIMBAL = Path(__file__).resolve().parent / 'pan_tilt.urdf'

#: a camera mounted 0.1 m to the right of, 0.05 m above and 0.2 m ahead of the tilt axis,
#: with the pan joint mounted yawed by 90 degrees: every offset the solver must handle
OFFSET_RIG = """<?xml version="1.0"?>
<robot name="offset_rig">
  <link name="base_link"/>
  <joint name="slider" type="prismatic">
    <parent link="base_link"/><child link="carriage"/>
    <origin xyz="0 0 0.1"/><axis xyz="1 0 0"/>
    <limit lower="-2" upper="2" velocity="1" effort="1"/>
  </joint>
  <link name="carriage"/>
  <joint name="pan" type="revolute">
    <parent link="carriage"/><child link="pan_link"/>
    <origin xyz="0.05 0 0.3" rpy="0 0 1.5707963267948966"/><axis xyz="0 0 1"/>
    <limit lower="-3.2" upper="3.2" velocity="1" effort="1"/>
  </joint>
  <link name="pan_link"/>
  <joint name="tilt" type="revolute">
    <parent link="pan_link"/><child link="tilt_link"/>
    <origin xyz="0 0 0.2"/><axis xyz="0 -1 0"/>
    <limit lower="-1.6" upper="1.6" velocity="1" effort="1"/>
  </joint>
  <link name="tilt_link"/>
  <joint name="camera_joint" type="fixed">
    <parent link="tilt_link"/><child link="camera_link"/>
    <origin xyz="0.2 -0.1 0.05"/>
  </joint>
  <link name="camera_link"/>
</robot>
"""


def sight_of(chain: AimingChain, positions: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    pose = chain.aim_pose(positions)
    return pose[:3, 3], pose[:3, 0]


def test_forward_kinematics_of_the_virtual_gimbal_by_hand() -> None:
    chain = AimingChain.from_file(VIRTUAL_GIMBAL)
    assert (chain.base_frame, chain.pan_joint, chain.tilt_joint) == ('base_link', 'pan', 'tilt')
    origin, sight = sight_of(chain, {'pan': 0.0, 'tilt': 0.0})
    assert origin == pytest.approx([0.05, 0.0, 0.20])
    assert sight == pytest.approx([1.0, 0.0, 0.0])
    # pan +90 deg: the camera offset swings to +y (left), the sight looks along +y
    origin, sight = sight_of(chain, {'pan': math.pi / 2, 'tilt': 0.0})
    assert origin == pytest.approx([0.0, 0.05, 0.20], abs=1e-12)
    assert sight == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)
    # tilt +90 deg about the axis 0.18 m up: the camera looks straight up
    origin, sight = sight_of(chain, {'pan': 0.0, 'tilt': math.pi / 2})
    assert origin == pytest.approx([-0.02, 0.0, 0.23], abs=1e-12)
    assert sight == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)


@pytest.mark.parametrize(('target', 'pan', 'tilt'), [
    ((2.0, 0.0, 0.2), 0.0, 0.0),             # straight ahead at camera height
    ((0.0, 3.0, 0.2), math.pi / 2, 0.0),     # to the left
    ((0.0, -3.0, 0.2), -math.pi / 2, 0.0),   # to the right
    ((-3.0, 0.0, 0.2), math.pi, 0.0),        # behind
])
def test_solve_simple_directions(target, pan, tilt) -> None:
    chain = AimingChain.from_file(VIRTUAL_GIMBAL)
    angles = chain.solve(target, {})
    assert wrap_angle(angles['pan'] - pan) == pytest.approx(0.0, abs=1e-9)
    assert angles['tilt'] == pytest.approx(tilt, abs=1e-9)


def test_solve_up_includes_the_camera_offset() -> None:
    chain = AimingChain.from_file(VIRTUAL_GIMBAL)
    angles = chain.solve((1.0, 0.0, 1.18), {})
    assert angles['pan'] == pytest.approx(0.0, abs=1e-9)
    # The camera sits 0.02 m above the tilt axis (0.18 m): 45 deg from the axis is not it.
    assert angles['tilt'] > 0.0
    assert angles['tilt'] != pytest.approx(math.pi / 4, abs=1e-3)
    origin, sight = sight_of(chain, angles)
    to_target = np.array([1.0, 0.0, 1.18]) - origin
    assert np.cross(sight, to_target / np.linalg.norm(to_target)) == pytest.approx(
        [0, 0, 0], abs=1e-9)


def test_solve_puts_random_targets_on_the_line_of_sight_with_every_offset() -> None:
    chain = AimingChain.from_xml(OFFSET_RIG)
    assert chain.movable_joints == ['slider', 'pan', 'tilt']
    rng = random.Random(7)
    for _ in range(200):
        slider = rng.uniform(-1.0, 1.0)
        distance = rng.uniform(1.0, 20.0)
        azimuth, elevation = rng.uniform(-math.pi, math.pi), rng.uniform(-1.3, 1.3)
        target = np.array([
            distance * math.cos(elevation) * math.cos(azimuth) + slider,
            distance * math.cos(elevation) * math.sin(azimuth),
            distance * math.sin(elevation) + 0.6,
        ])
        angles = chain.solve(tuple(target), {'slider': slider})
        assert abs(angles['tilt']) <= math.pi / 2
        origin, sight = sight_of(chain, {'slider': slider, **angles})
        direction = (target - origin) / np.linalg.norm(target - origin)
        assert float(sight @ direction) == pytest.approx(1.0, abs=1e-9)


def test_solve_refuses_what_it_cannot_do() -> None:
    chain = AimingChain.from_xml(OFFSET_RIG)
    with pytest.raises(KinematicsError, match='no position known'):
        chain.solve((1.0, 0.0, 0.0), {})
    with pytest.raises(KinematicsError, match='not a finite point'):
        chain.solve((math.nan, 0.0, 0.0), {'slider': 0.0})
    # inside the camera's 0.1 m lateral offset around the pan axis: no pan sees it
    with pytest.raises(KinematicsError, match='too close'):
        chain.solve((0.05, 0.0, 0.6), {'slider': 0.0})


def test_descriptions_that_cannot_aim_are_refused() -> None:
    with pytest.raises(KinematicsError, match='no link'):
        AimingChain.from_file(VIRTUAL_GIMBAL, aim_frame='lens')
    one_joint = OFFSET_RIG.replace('type="revolute">\n    <parent link="pan_link"/>',
                                   'type="fixed">\n    <parent link="pan_link"/>')
    with pytest.raises(KinematicsError, match='exactly two revolute'):
        AimingChain.from_xml(one_joint)
    with pytest.raises(KinematicsError, match='cannot parse'):
        AimingChain.from_xml('<robot name="x"><link></robot>')
    with pytest.raises(KinematicsError, match='cannot read'):
        AimingChain.from_file('/nonexistent/description.urdf')


def test_nearest_in_limits_picks_the_turn_closest_to_now() -> None:
    assert nearest_in_limits(0.1, -math.pi, math.pi, 3.0) == pytest.approx(0.1)
    assert nearest_in_limits(3.0, -10.0, 10.0, -3.0) == pytest.approx(3.0 - 2 * math.pi)
    assert nearest_in_limits(3.0, -10.0, 10.0, 8.0) == pytest.approx(3.0 + 2 * math.pi)
    assert nearest_in_limits(-3.0, -1.0, 1.0, 0.0) is None
    assert nearest_in_limits(2.5, 3.0, 9.0, 0.0) == pytest.approx(2.5 + 2 * math.pi)
    assert nearest_in_limits(-math.pi / 2, -10.0, 10.0, math.pi / 2) == pytest.approx(-math.pi / 2)
