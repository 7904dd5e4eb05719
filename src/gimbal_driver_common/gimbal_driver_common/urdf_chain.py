"""The links and joints of a URDF, read with the standard library (no ROS, no lxml).

What :class:`~gimbal_driver_common.kinematics.AimingChain` uses of a robot description: the
robot's name, its link names, and each joint's type, parent and child links, ``<origin>``,
``<axis>`` and ``<limit>``, with the defaults and the required attributes of the URDF
specification as ``urdf_parser_py`` (urdfdom-py) reads them: an absent origin is None
(identity), an origin without ``rpy`` has no rotation, an absent axis is None (the URDF's
``1 0 0``), a ``<limit>`` without ``lower``/``upper`` has them 0, and its ``effort`` and
``velocity`` are required. ``test/test_urdf_chain.py`` holds it to urdf_parser_py on every
installed description.

Why not urdf_parser_py itself: it needs lxml, 1.3 MB of every driver node's memory of the
1.6 MB the two cost together (bench/README.md, "What a node imports"), for a file that is
read once at start-up; the standard library's ElementTree costs 0.3 MB. Only the direct
children of ``<robot>`` count (a ``<joint>`` inside ``<transmission>`` or ``<gazebo>`` is
not a joint), as in urdf_parser_py.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass


class UrdfError(ValueError):
    """The text is not a URDF this reader can use (malformed XML, a required element or
    attribute missing, a number that is not one, a chain that does not connect)."""


@dataclass(frozen=True)
class Origin:
    xyz: list[float]
    rpy: list[float]


@dataclass(frozen=True)
class Limit:
    lower: float
    upper: float
    velocity: float
    effort: float


@dataclass(frozen=True)
class Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: Origin | None
    axis: list[float] | None
    limit: Limit | None


@dataclass(frozen=True)
class Description:
    """A robot description: its name, link names in order, joints by name."""

    name: str
    links: list[str]
    joints: dict[str, Joint]

    def root(self) -> str:
        """The one link that is no joint's child."""
        children = {joint.child for joint in self.joints.values()}
        roots = [link for link in self.links if link not in children]
        if len(roots) != 1:
            raise UrdfError(f'the description needs exactly one root link; it has {roots}')
        return roots[0]

    def chain(self, base: str, tip: str) -> list[str]:
        """The joint names from ``base`` down to ``tip``, in order."""
        by_child = {joint.child: joint for joint in self.joints.values()}
        names: list[str] = []
        link = tip
        while link != base:
            joint = by_child.get(link)
            if joint is None or len(names) > len(self.joints):
                raise UrdfError(f'no chain of joints from {base!r} to {tip!r}')
            names.append(joint.name)
            link = joint.parent
        return names[::-1]


def _required(element: ElementTree.Element, attribute: str) -> str:
    value = element.get(attribute)
    if value is None:
        raise UrdfError(f'<{element.tag}> has no {attribute!r} attribute')
    return value


def _number(element: ElementTree.Element, attribute: str, default: float | None = None,
            ) -> float:
    text = element.get(attribute)
    if text is None:
        if default is None:
            raise UrdfError(f'<{element.tag}> has no {attribute!r} attribute')
        return default
    try:
        return float(text)
    except ValueError:
        raise UrdfError(f'<{element.tag} {attribute}={text!r}> is not a number') from None


def _vector(element: ElementTree.Element, attribute: str) -> list[float] | None:
    text = element.get(attribute)
    if text is None:
        return None
    try:
        values = [float(part) for part in text.split()]
    except ValueError:
        values = []
    if len(values) != 3:
        raise UrdfError(f'<{element.tag} {attribute}={text!r}> is not 3 numbers')
    return values


def _link_of(joint: ElementTree.Element, tag: str) -> str:
    element = joint.find(tag)
    if element is None:
        raise UrdfError(f'joint {joint.get("name")!r} has no <{tag}>')
    return _required(element, 'link')


def _joint(element: ElementTree.Element) -> Joint:
    origin = element.find('origin')
    axis = element.find('axis')
    limit = element.find('limit')
    return Joint(
        name=_required(element, 'name'), type=_required(element, 'type'),
        parent=_link_of(element, 'parent'), child=_link_of(element, 'child'),
        origin=None if origin is None else Origin(
            xyz=_vector(origin, 'xyz') or [0.0, 0.0, 0.0],
            rpy=_vector(origin, 'rpy') or [0.0, 0.0, 0.0]),
        axis=None if axis is None else _vector(axis, 'xyz'),
        limit=None if limit is None else Limit(
            lower=_number(limit, 'lower', 0.0), upper=_number(limit, 'upper', 0.0),
            velocity=_number(limit, 'velocity'), effort=_number(limit, 'effort')),
    )


def read_description(xml: str) -> Description:
    """The links and joints of a URDF document; :class:`UrdfError` if it has none to read."""
    try:
        robot = ElementTree.fromstring(xml)
    except ElementTree.ParseError as exc:
        raise UrdfError(str(exc)) from None
    if robot.tag != 'robot':
        raise UrdfError(f'the document is <{robot.tag}>, not <robot>')
    joints: dict[str, Joint] = {}
    for element in robot.findall('joint'):
        joint = _joint(element)
        joints[joint.name] = joint
    return Description(name=robot.get('name', ''),
                       links=[_required(link, 'name') for link in robot.findall('link')],
                       joints=joints)
