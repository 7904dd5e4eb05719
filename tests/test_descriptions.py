"""Every package's URDF loads, matches its node's default joints and limits, and has
REP-103 signs (checked by forward kinematics): base_link -> [slider] -> pan -> tilt ->
camera_link, positive pan turns the line of sight counter-clockwise seen from above,
positive tilt raises it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('urdf_parser_py', reason='needs urdfdom-py (make build)')
pytest.importorskip('rclpy', reason='the node classes need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='the node classes need the built workspace')
from urdf_parser_py.urdf import URDF

from gimbal_driver_common.kinematics import AimingChain
from gimbal_driver_common.registry import drivers, resolve

SRC = Path(__file__).resolve().parent.parent / 'src'
#: package -> (description file, node class) of every registered driver
DESCRIPTIONS = {spec.package: (spec.description, spec.node_class) for spec in drivers()}


def per_joint(values, count: int) -> list[float]:
    """The base node's expansion of a short default list (last value repeated)."""
    values = list(values)
    return (values + values[-1:] * count)[:count]


def description(pkg: str) -> Path:
    return SRC / pkg / 'urdf' / DESCRIPTIONS[pkg][0]


def test_every_package_ships_a_description() -> None:
    shipped = {path.parent.parent.name for path in SRC.glob('*/urdf/*.urdf')}
    assert shipped == set(DESCRIPTIONS)


@pytest.mark.parametrize('pkg', list(DESCRIPTIONS))
def test_joints_equal_the_node_defaults(pkg: str) -> None:
    robot = URDF.from_xml_file(str(description(pkg)))
    node = resolve(DESCRIPTIONS[pkg][1])
    names = list(node.DEFAULT_JOINT_NAMES)
    assert robot.get_root() == 'base_link'
    chain = robot.get_chain('base_link', 'camera_link', joints=True, links=False)
    joints = {joint.name: joint for joint in robot.joints}
    movable = [name for name in chain if joints[name].type != 'fixed']
    assert movable == names, f'{pkg}: URDF chain {movable} vs node {names}'
    lower = per_joint(node.DEFAULT_POSITION_MIN, len(names))
    upper = per_joint(node.DEFAULT_POSITION_MAX, len(names))
    velocity = per_joint(node.DEFAULT_VELOCITY_MAX, len(names))
    for i, name in enumerate(names):
        joint = joints[name]
        expected_type = 'prismatic' if name == 'slider' else 'revolute'
        assert joint.type == expected_type
        assert joint.limit.lower == pytest.approx(lower[i], abs=1e-12), name
        assert joint.limit.upper == pytest.approx(upper[i], abs=1e-12), name
        assert joint.limit.velocity == pytest.approx(velocity[i], abs=1e-12), name


@pytest.mark.parametrize('pkg', list(DESCRIPTIONS))
def test_signs_follow_rep103_by_forward_kinematics(pkg: str) -> None:
    chain = AimingChain.from_file(description(pkg))
    pan, tilt = chain.pan_joint, chain.tilt_joint
    zero = {name: 0.0 for name in chain.movable_joints}

    def sight(**moved: float) -> np.ndarray:
        return chain.aim_pose({**zero, **moved})[:3, 0]

    assert sight() == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)  # looks forward (+x) at zero
    turned = sight(**{pan: 0.3})
    assert turned == pytest.approx([math.cos(0.3), math.sin(0.3), 0.0], abs=1e-12)  # left
    raised = sight(**{tilt: 0.3})
    assert raised == pytest.approx([math.cos(0.3), 0.0, math.sin(0.3)], abs=1e-12)  # up
    if 'slider' in chain.movable_joints:  # positive slider travels along the track (+x)
        start = chain.aim_pose(zero)[:3, 3]
        moved = chain.aim_pose({**zero, 'slider': 0.5})[:3, 3]
        assert moved - start == pytest.approx([0.5, 0.0, 0.0], abs=1e-12)


@pytest.mark.parametrize('pkg', list(DESCRIPTIONS))
def test_the_installed_description_is_the_source(pkg: str) -> None:
    packages = pytest.importorskip('ament_index_python.packages')
    try:
        share = Path(packages.get_package_share_directory(pkg))
    except packages.PackageNotFoundError:
        pytest.skip(f'{pkg} is not built (make build)')
    installed = share / 'urdf' / DESCRIPTIONS[pkg][0]
    assert installed.read_text() == description(pkg).read_text()
