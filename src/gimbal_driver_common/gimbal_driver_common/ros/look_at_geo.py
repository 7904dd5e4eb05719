"""``~/look_at_geo``: point the device's camera/tool frame at a place on Earth.

A part of the base node (its ``look_at_geo_server`` attribute, :class:`LookAtGeoServer`),
beside ``~/look_at`` (:mod:`.look_at`), handed the node's public side (:class:`GeoAimNode`),
the look_at part (the URDF solver and checks) and the motion actions (the move path); it
owns the site and pose-quality parameters. The target (WGS84
latitude, longitude, altitude above the ellipsoid) goes to the base frame through
:mod:`gimbal_driver_common.geodesy` (WGS84 -> ECEF -> ENU at the device -> base frame by
its attitude), from the pose the device reports (its ``Geolocation`` capability) with the
``site_position`` / ``site_orientation`` parameters overriding it part by part. Then it
aims through the same URDF solver, limit checks and move path as ``~/look_at``; a device
that points at targets itself (its ``TargetPointing`` capability, Capture's GPS_GoToTarget)
is given the target instead, after the same checks, when it aims from the same pose.
Nothing is sent for a refused goal: no pose, a fix too old or too poor, a target beyond
the limits.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Protocol

from rclpy.action.server import ServerGoalHandle

from gimbal_driver_common.controller import GimbalController
from gimbal_driver_common.device import Device, TargetPointing
from gimbal_driver_common.errors import GimbalError, InvalidRequest
from gimbal_driver_common.geodesy import (
    Attitude,
    GeoPoint,
    GeoPose,
    PoseLimits,
    base_frame_point,
    describe_target,
    resolve_pose,
)
from gimbal_driver_common.policies import Motion
from gimbal_driver_common.ros.actions import MotionActions
from gimbal_driver_common.ros.look_at import (
    ConfiguringHost,
    LookAtRefused,
    LookAtServer,
    MoveGoalView,
)
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_msgs.action import LookAtGeo, MoveTo

#: site_orientation element ranges (rad): roll, pitch, yaw
ORIENTATION_RANGES = (('roll', -math.pi, math.pi), ('pitch', -math.pi / 2, math.pi / 2),
                      ('yaw', -2.0 * math.pi, 2.0 * math.pi))


def site_position_from(value: Any) -> GeoPoint | None:
    """The ``site_position`` parameter as a point (None when empty); ParameterError else."""
    values = list(value)
    if not values:
        return None
    if len(values) != 3:
        raise ParameterError(
            f"parameter 'site_position': give [latitude deg, longitude deg, altitude m above "
            f'the WGS84 ellipsoid] or [] (unknown), got {values}')
    try:
        return GeoPoint(*values).checked("parameter 'site_position'")
    except InvalidRequest as exc:
        raise ParameterError(str(exc)) from exc


def site_orientation_from(value: Any) -> Attitude | None:
    """The ``site_orientation`` parameter as an attitude (None when empty); ParameterError
    else."""
    values = list(value)
    if not values:
        return None
    if len(values) != 3:
        raise ParameterError(
            "parameter 'site_orientation': give [roll, pitch, yaw] in rad of the base frame "
            f'in ENU (yaw counter-clockwise from east) or [] (unknown), got {values}')
    for item, (name, low, high) in zip(values, ORIENTATION_RANGES, strict=True):
        if not (math.isfinite(item) and low <= item <= high):
            raise ParameterError(f"parameter 'site_orientation': {name} {item} outside "
                                 f'[{low:.4f}, {high:.4f}] rad')
    return Attitude(*values)


@dataclass(frozen=True)
class GeoAim:
    """A planned look_at_geo goal: the joints and where they go, and how."""

    target: GeoPoint
    pose: GeoPose
    joints: list[str]
    positions: list[float]
    what: str                              # the target as seen from the device
    pointing: TargetPointing | None = None  # the device points itself; None: our move


class GeoAimNode(ConfiguringHost, Protocol):
    """What ~/look_at_geo uses of the node (:class:`~.base_node.GimbalDriverNode`)."""

    @property
    def controller(self) -> GimbalController | None: ...

    @property
    def motion(self) -> Motion | None: ...

    @property
    def device(self) -> Device | None: ...

    def runtime_parameter(self, name: str, apply: Callable[[object], None] | str,
                          send: Callable[[object], None] | None = None,
                          busy: Callable[[], str | None] | None = None,
                          check: Callable[[object], object] | None = None) -> None:
        """Let ``ros2 param set`` change ``name`` while the node runs."""


class LookAtGeoServer:
    """Declares the site and pose-quality parameters and serves ~/look_at_geo."""

    def __init__(self, node: GeoAimNode, look_at: LookAtServer,
                 actions: MotionActions) -> None:
        self._node = node
        self._look_at = look_at
        self._actions = actions
        self.site_position: GeoPoint | None = site_position_from(node.declare_param(
            'site_position', [],
            'where the device stands: [latitude deg, longitude deg, altitude m above the '
            'WGS84 ellipsoid]; overrides the device\'s own position; [] = unknown',
            element_type=float))
        self.site_orientation: Attitude | None = site_orientation_from(node.declare_param(
            'site_orientation', [],
            'orientation of the base frame in ENU: [roll, pitch, yaw] rad (REP-103, yaw '
            'counter-clockwise from east = pi/2 - compass heading); overrides the device\'s '
            'own; [] = unknown', element_type=float))
        self.pose_limits = PoseLimits(
            max_age=node.declare_param(
                'pose_max_age', PoseLimits.max_age,
                's: a device position or heading older than this is refused by ~/look_at_geo',
                value_range=(0.05, 3600.0)),
            max_position_error=node.declare_param(
                'pose_max_position_error', PoseLimits.max_position_error,
                'm: a device position whose reported accuracy (1 sigma) is worse is refused',
                value_range=(0.01, 100000.0)),
            max_heading_error=node.declare_param(
                'pose_max_heading_error', PoseLimits.max_heading_error,
                'rad: a device heading whose reported accuracy (1 sigma) is worse is refused',
                value_range=(1e-5, math.pi)))

        def set_site_position(value: object) -> None:
            self.site_position = site_position_from(value)

        def set_site_orientation(value: object) -> None:
            self.site_orientation = site_orientation_from(value)

        def set_limit(field_name: str) -> Callable[[object], None]:
            def apply(value: object) -> None:
                assert isinstance(value, float | int)  # declared as a float parameter
                self.pose_limits = replace(self.pose_limits, **{field_name: float(value)})
            return apply

        node.runtime_parameter('site_position', set_site_position, check=site_position_from)
        node.runtime_parameter('site_orientation', set_site_orientation,
                               check=site_orientation_from)
        for name, field_name in (('pose_max_age', 'max_age'),
                                 ('pose_max_position_error', 'max_position_error'),
                                 ('pose_max_heading_error', 'max_heading_error')):
            node.runtime_parameter(name, set_limit(field_name))
        node.create_accepting_action_server(LookAtGeo, '~/look_at_geo',
                                            self._execute_look_at_geo)

    def device_pose(self) -> GeoPose:
        """The pose to aim from (the device's, overridden by the site parameters); raises
        GimbalError (PoseUnavailable naming what is missing, too old or too poor)."""
        device, controller = self._node.device, self._node.controller
        geolocation = device.capabilities.geolocation if device is not None else None
        reported = (controller.call(geolocation.pose)
                    if geolocation is not None and controller is not None else None)
        return resolve_pose(reported, self.site_position, self.site_orientation,
                            self.pose_limits)

    def plan_look_at_geo(self, goal: LookAtGeo.Goal) -> GeoAim:
        """Check everything before anything is sent; raises LookAtRefused with the reason."""
        self._look_at.aim_checks('look_at_geo', goal.speed)
        try:
            target = GeoPoint(goal.latitude, goal.longitude, goal.altitude).checked('target')
            pose = self.device_pose()
        except GimbalError as exc:
            raise LookAtRefused(str(exc)) from exc
        what = describe_target(target, pose)
        point = base_frame_point(target, pose)
        joints, positions = self._look_at.plan_aim(
            (float(point[0]), float(point[1]), float(point[2])), what)
        device = self._node.device
        pointing = device.capabilities.target_pointing if device is not None else None
        if pointing is not None and (not pose.from_device or pointing.refusal(pose, goal.speed)):
            pointing = None
        return GeoAim(target, pose, joints, positions, what, pointing)

    def _execute_look_at_geo(self, goal_handle: ServerGoalHandle) -> LookAtGeo.Result:
        result = LookAtGeo.Result()
        try:
            aim = self.plan_look_at_geo(goal_handle.request)
        except LookAtRefused as exc:
            return self._look_at.refuse_aim(goal_handle, result, 'look_at_geo', exc)
        path = ("the device's own target pointing" if aim.pointing is not None
                else 'a driver move')
        self._node.get_logger().info(
            f'look_at_geo: {aim.what}, seen {aim.pose}: ' + ', '.join(
                f'{j} {p:+.4f} rad' for j, p in zip(aim.joints, aim.positions, strict=True))
            + f' by {path}')
        if aim.pointing is None:
            self._look_at.move_aim(goal_handle, result, aim.joints, aim.positions,
                                   LookAtGeo.Feedback)
        else:
            targets = dict(zip(aim.joints, aim.positions, strict=True))
            try:
                motion = self._node.motion
                if motion is None:
                    raise LookAtRefused('the node is not configured')
                _, targets = motion.point_at(aim.pointing, aim.target, targets)
            except (GimbalError, LookAtRefused) as exc:
                goal_handle.abort()
                current = self._node.current_positions()
                result.joint_names = aim.joints
                result.positions = [current.get(j, math.nan) for j in aim.joints]
                result.success = False
                result.message = f'look_at_geo: the device refused its target pointing: {exc}'
                return result
            view = MoveGoalView(goal_handle, MoveTo.Goal(), LookAtGeo.Feedback)
            moved = self._actions.finish_move(view, targets, 0.0)
            result.success, result.message = moved.success, moved.message
            result.positions, result.joint_names = list(moved.positions), aim.joints
        result.message = f'{result.message}: {aim.what}, by {path}'
        return result
