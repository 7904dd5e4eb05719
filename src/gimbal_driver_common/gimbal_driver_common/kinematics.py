"""Pan and tilt angles that point a URDF chain's camera/tool frame at a point (no ROS).

The chain is read from the device's URDF with ``urdf_parser_py`` (PyPI: urdfdom-py, the
parser ROS itself ships): base link -> [prismatic/other joints] -> pan -> tilt -> the aim
frame, whose +x axis is the line of sight (REP-103 body frame: x forward, z up). Every
offset between the joints counts, so a camera mounted beside or above the tilt axis still
looks exactly at the point.

The two revolute (or continuous) joints of the chain are pan (first from the base) and
tilt (second); any other movable joint (the Kessler slider) is held where it is. The
solution is found by Newton iteration on the line-of-sight error, which needs no
assumption about axis directions or mounting rotations beyond what the URDF says.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gimbal_driver_common.orientation import wrap_angle

if TYPE_CHECKING:  # the parser (and lxml with it) is loaded by the first chain read
    from urdf_parser_py.urdf import URDF

#: joint types whose position is a rotation about ``axis``
REVOLUTE_TYPES = ('revolute', 'continuous')
#: joint types that move at all
MOVABLE_TYPES = (*REVOLUTE_TYPES, 'prismatic')
#: default name of the frame whose +x axis is pointed at the target
DEFAULT_AIM_FRAME = 'camera_link'

_SOLVE_TOLERANCE = 1e-10  # rad of line-of-sight error: converged
_MAX_ITERATIONS = 60
_MAX_STEP = 0.5  # rad per Newton step: keeps the iteration away from wild jumps
#: (pan, tilt) starting points of the solver, tried in order
_STARTS = [(pan, tilt) for tilt in (0.0, 0.9, -0.9)
           for pan in (0.0, math.pi / 2, math.pi, -math.pi / 2)]


class KinematicsError(ValueError):
    """The description cannot be used, or the point cannot be looked at."""


@dataclass(frozen=True)
class ChainJoint:
    """One joint of the base-to-aim-frame chain, as the URDF gives it."""

    name: str
    type: str
    origin: np.ndarray  # 4x4 transform parent link -> joint frame at position 0
    axis: np.ndarray  # unit vector in the joint frame
    lower: float
    upper: float
    velocity: float

    def transform(self, position: float) -> np.ndarray:
        """Parent link -> child link at ``position`` (rad or m)."""
        motion = np.eye(4)
        if self.type in REVOLUTE_TYPES:
            motion[:3, :3] = _axis_angle(self.axis, position)
        elif self.type == 'prismatic':
            motion[:3, 3] = self.axis * position
        return self.origin @ motion


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` about the unit vector ``axis`` (Rodrigues)."""
    x, y, z = axis
    skew = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * skew + (1.0 - math.cos(angle)) * (skew @ skew)


def rotation_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rotation matrix of fixed-axis roll, pitch, yaw (R = Rz Ry Rx): URDF ``rpy`` and
    REP-103 / tf2 ``setRPY`` alike; its columns are the rotated frame's axes."""
    return (
        _axis_angle(np.array([0.0, 0.0, 1.0]), yaw)
        @ _axis_angle(np.array([0.0, 1.0, 0.0]), pitch)
        @ _axis_angle(np.array([1.0, 0.0, 0.0]), roll)
    )


def _origin(xyz: Sequence[float] | None, rpy: Sequence[float] | None) -> np.ndarray:
    """URDF <origin>: translation, then fixed-axis roll, pitch, yaw (R = Rz Ry Rx)."""
    matrix = np.eye(4)
    matrix[:3, :3] = rotation_rpy(*(rpy or (0.0, 0.0, 0.0)))
    matrix[:3, 3] = xyz or (0.0, 0.0, 0.0)
    return matrix


class AimingChain:
    """The pan/tilt chain of a device description and its aiming solution."""

    def __init__(self, robot: URDF, aim_frame: str = DEFAULT_AIM_FRAME) -> None:
        links = {link.name for link in robot.links}
        if aim_frame not in links:
            raise KinematicsError(
                f'the description has no link {aim_frame!r} to aim (links: {sorted(links)})'
            )
        self.robot_name: str = robot.name
        self.base_frame: str = robot.get_root()
        self.aim_frame = aim_frame
        joints_by_name = {joint.name: joint for joint in robot.joints}
        self.joints: list[ChainJoint] = []
        for name in robot.get_chain(self.base_frame, aim_frame, joints=True, links=False):
            joint = joints_by_name[name]
            origin = joint.origin
            axis = np.array(joint.axis if joint.axis is not None else (1.0, 0.0, 0.0), float)
            if joint.type in MOVABLE_TYPES:
                norm = float(np.linalg.norm(axis))
                if norm == 0.0:
                    raise KinematicsError(f'joint {name!r} has a zero axis')
                axis = axis / norm
            limit = joint.limit
            self.joints.append(ChainJoint(
                name=name, type=joint.type,
                origin=_origin(origin.xyz if origin else None, origin.rpy if origin else None),
                axis=axis,
                lower=float(limit.lower) if limit is not None and limit.lower is not None
                else -math.inf,
                upper=float(limit.upper) if limit is not None and limit.upper is not None
                else math.inf,
                velocity=float(limit.velocity) if limit is not None and limit.velocity
                else math.inf,
            ))
        revolute = [j.name for j in self.joints if j.type in REVOLUTE_TYPES]
        if len(revolute) != 2:
            raise KinematicsError(
                f'the chain {self.base_frame} -> {aim_frame} needs exactly two revolute joints '
                f'(pan, then tilt); it has {revolute}'
            )
        self.pan_joint, self.tilt_joint = revolute
        unsupported = [j.name for j in self.joints if j.type not in (*MOVABLE_TYPES, 'fixed')]
        if unsupported:
            raise KinematicsError(f'unsupported joint type in the chain: {unsupported}')

    @classmethod
    def from_xml(cls, xml: str, aim_frame: str = DEFAULT_AIM_FRAME) -> AimingChain:
        # imported here: 1.3 MB of every node's memory with lxml, for a feature some never
        # use (bench/README.md, "What a node imports")
        from urdf_parser_py.urdf import URDF

        try:
            robot = URDF.from_xml_string(xml)
        except Exception as exc:  # the parser raises assorted types
            raise KinematicsError(f'cannot parse the URDF: {exc}') from exc
        return cls(robot, aim_frame)

    @classmethod
    def from_file(cls, path: str | Path, aim_frame: str = DEFAULT_AIM_FRAME) -> AimingChain:
        try:
            xml = Path(path).read_text(encoding='utf-8')
        except OSError as exc:
            raise KinematicsError(f'cannot read the description {path}: {exc}') from exc
        return cls.from_xml(xml, aim_frame)

    @property
    def movable_joints(self) -> list[str]:
        return [j.name for j in self.joints if j.type in MOVABLE_TYPES]

    def aim_pose(self, positions: Mapping[str, float]) -> np.ndarray:
        """4x4 pose of the aim frame in the base frame (forward kinematics)."""
        pose = np.eye(4)
        for joint in self.joints:
            pose = pose @ joint.transform(float(positions.get(joint.name, 0.0)))
        return pose

    def line_of_sight_error(
        self, positions: Mapping[str, float], target: np.ndarray
    ) -> tuple[float, float, float]:
        """(azimuth, elevation, distance) of ``target`` seen from the aim frame."""
        pose = self.aim_pose(positions)
        local = pose[:3, :3].T @ (target - pose[:3, 3])
        x, y, z = (float(v) for v in local)
        return math.atan2(y, x), math.atan2(z, math.hypot(x, y)), math.sqrt(x * x + y * y + z * z)

    def solve(
        self, target: tuple[float, float, float], positions: Mapping[str, float]
    ) -> dict[str, float]:
        """Pan and tilt (rad, pan in (-pi, pi], tilt in [-pi/2, pi/2] where the geometry
        allows) that put ``target`` (base frame, m) on the aim frame's +x axis.

        ``positions`` gives the other movable joints (held) and is not changed. Raises
        KinematicsError when the point is too close to be looked at.
        """
        point = np.array(target, float)
        if not np.all(np.isfinite(point)):
            raise KinematicsError(f'target {tuple(target)} is not a finite point')
        missing = [n for n in self.movable_joints
                   if n not in (self.pan_joint, self.tilt_joint) and n not in positions]
        if missing:
            raise KinematicsError(f'no position known for joint(s) {missing}')
        state = dict(positions)
        # Newton from a few starting points: one near the answer always converges, while
        # a start far off (a steep target seen from tilt 0) can wander.
        for start in _STARTS:
            angles = self._newton(point, state, start)
            if angles is None:
                continue
            pan, tilt = angles
            if abs(tilt) > math.pi / 2 + 1e-9:  # looking over the top: the other branch
                angles = self._newton(
                    point, state, (wrap_angle(pan + math.pi), wrap_angle(math.pi - tilt)))
                if angles is None or abs(angles[1]) > math.pi / 2 + 1e-9:
                    continue
                pan, tilt = angles
            return {self.pan_joint: pan, self.tilt_joint: tilt}
        raise KinematicsError(
            f'cannot point {self.aim_frame} at ({point[0]:.3f}, {point[1]:.3f}, '
            f'{point[2]:.3f}) m in {self.base_frame}: the point is too close to the device '
            'for the offsets of its description'
        )

    def _newton(
        self, point: np.ndarray, state: dict[str, float], start: tuple[float, float]
    ) -> tuple[float, float] | None:
        """Pan and tilt (wrapped) from ``start``, or None if the iteration fails."""
        angles = np.array(start, float)
        names = (self.pan_joint, self.tilt_joint)

        def error(values: np.ndarray) -> tuple[np.ndarray, float]:
            state.update(zip(names, values, strict=True))
            azimuth, elevation, distance = self.line_of_sight_error(state, point)
            return np.array([azimuth, elevation]), distance

        for _ in range(_MAX_ITERATIONS):
            residual, distance = error(angles)
            if distance < 1e-9:
                return None
            if float(np.max(np.abs(residual))) < _SOLVE_TOLERANCE:
                return wrap_angle(float(angles[0])), wrap_angle(float(angles[1]))
            jacobian = np.empty((2, 2))
            for column in range(2):
                nudged = angles.copy()
                nudged[column] += 1e-7
                jacobian[:, column] = (error(nudged)[0] - residual) / 1e-7
            try:
                step = np.linalg.solve(jacobian, -residual)
            except np.linalg.LinAlgError:
                return None
            largest = float(np.max(np.abs(step)))
            if largest > _MAX_STEP:
                step *= _MAX_STEP / largest
            angles = angles + step
        return None


def nearest_in_limits(angle: float, lower: float, upper: float, current: float) -> float | None:
    """The ``angle + 2*pi*k`` inside [lower, upper] closest to ``current`` (on a tie, the
    one nearer zero), or None."""
    if not math.isfinite(current):
        current = 0.0
    turns = round((current - angle) / (2.0 * math.pi))
    candidates = [angle + 2.0 * math.pi * k for k in range(turns - 1, turns + 2)]
    candidates += [angle + 2.0 * math.pi * k for k in
                   (math.ceil((lower - angle) / (2.0 * math.pi)),
                    math.floor((upper - angle) / (2.0 * math.pi)))
                   if math.isfinite(lower) and math.isfinite(upper)]
    inside = [c for c in candidates if lower - 1e-9 <= c <= upper + 1e-9]
    if not inside:
        return None
    return min(inside, key=lambda c: (round(abs(c - current), 9), abs(c)))
