"""The standard-library URDF reader (urdf_chain.py) against urdf_parser_py, the parser ROS
ships: the same links, joints, origins, axes, limits, root and chain for every description a
registered driver installs and for the test descriptions, and the same refusals."""

from __future__ import annotations

from pathlib import Path

import pytest
from ament_index_python.packages import get_package_share_directory

from gimbal_driver_common.kinematics import DEFAULT_AIM_FRAME, AimingChain, KinematicsError
from gimbal_driver_common.registry import drivers
from gimbal_driver_common.urdf_chain import UrdfError, read_description

urdf = pytest.importorskip('urdf_parser_py.urdf', reason='needs urdfdom-py (make build)')

HERE = Path(__file__).resolve().parent


def descriptions() -> list[Path]:
    installed = [Path(get_package_share_directory(spec.package), 'urdf', spec.description)
                 for spec in drivers()]
    return [*installed, *sorted(HERE.glob('*.urdf'))]


@pytest.mark.parametrize('path', descriptions(), ids=lambda path: path.name)
def test_the_reader_agrees_with_urdf_parser_py(path: Path) -> None:
    xml = path.read_text(encoding='utf-8')
    ours, theirs = read_description(xml), urdf.URDF.from_xml_string(xml)
    assert ours.name == theirs.name
    assert ours.links == [link.name for link in theirs.links]
    assert list(ours.joints) == [joint.name for joint in theirs.joints]
    for joint in theirs.joints:
        mine = ours.joints[joint.name]
        assert (mine.type, mine.parent, mine.child) == (joint.type, joint.parent, joint.child)
        if joint.origin is None:
            assert mine.origin is None
        else:
            assert mine.origin is not None
            assert mine.origin.xyz == pytest.approx(list(joint.origin.xyz))
            assert mine.origin.rpy == pytest.approx(list(joint.origin.rpy))
        assert mine.axis == (None if joint.axis is None else pytest.approx(list(joint.axis)))
        if joint.limit is None:
            assert mine.limit is None
        else:
            assert mine.limit is not None
            assert (mine.limit.lower, mine.limit.upper, mine.limit.velocity,
                    mine.limit.effort) == pytest.approx(
                (joint.limit.lower, joint.limit.upper, joint.limit.velocity,
                 joint.limit.effort))
    root = theirs.get_root()
    assert ours.root() == root
    if DEFAULT_AIM_FRAME in ours.links:
        assert ours.chain(root, DEFAULT_AIM_FRAME) == theirs.get_chain(
            root, DEFAULT_AIM_FRAME, joints=True, links=False)


LIMITLESS = """<robot name="r"><link name="a"/><link name="b"/>
  <joint name="j" type="continuous"><parent link="a"/><child link="b"/>
  <limit effort="1" velocity="2"/></joint></robot>"""


def test_the_urdf_defaults_are_urdf_parser_pys() -> None:
    """A <limit> without lower/upper has them 0; a joint without <origin> or <axis> has
    none; an <origin> without rpy has no rotation."""
    ours, theirs = read_description(LIMITLESS), urdf.URDF.from_xml_string(LIMITLESS)
    limit = ours.joints['j'].limit
    assert limit is not None
    assert (limit.lower, limit.upper) == (theirs.joints[0].limit.lower,
                                          theirs.joints[0].limit.upper) == (0, 0)
    assert ours.joints['j'].origin is None and ours.joints['j'].axis is None
    shifted = read_description(LIMITLESS.replace('<limit', '<origin xyz="1 2 3"/><limit'))
    origin = shifted.joints['j'].origin
    assert origin is not None and (origin.xyz, origin.rpy) == ([1, 2, 3], [0, 0, 0])


@pytest.mark.parametrize('xml, words', [
    ('<robot name="x"><link></robot>', 'mismatched tag'),
    ('<model name="x"/>', 'not <robot>'),
    (LIMITLESS.replace(' velocity="2"', ''), "no 'velocity'"),
    (LIMITLESS.replace('velocity="2"', 'velocity="fast"'), 'not a number'),
    (LIMITLESS.replace('<limit', '<origin xyz="1 2"/><limit'), 'not 3 numbers'),
    (LIMITLESS.replace('<parent link="a"/>', ''), 'no <parent>'),
    (LIMITLESS.replace('<link name="a"/>', '<link/>'), "no 'name'"),
])
def test_what_cannot_be_read_is_refused_by_name(xml: str, words: str) -> None:
    with pytest.raises(UrdfError, match=words):
        read_description(xml)
    with pytest.raises(KinematicsError, match='cannot parse the URDF'):
        AimingChain.from_xml(xml)


def test_a_chain_that_does_not_connect_is_refused() -> None:
    two_roots = LIMITLESS.replace('<link name="b"/>', '<link name="b"/><link name="c"/>')
    with pytest.raises(UrdfError, match='exactly one root'):
        read_description(two_roots).root()
    with pytest.raises(KinematicsError, match='exactly one root'):
        AimingChain.from_xml(two_roots, aim_frame='b')
    with pytest.raises(UrdfError, match="no chain of joints from 'b' to 'a'"):
        read_description(LIMITLESS).chain('b', 'a')
