"""``~/look_at``: point the device's camera/tool frame at a geometry_msgs/PointStamped.

A part of the base node (its ``look_at_server`` attribute, :class:`LookAtServer`), handed
the node's public side (:class:`AimNode`), the node's motion actions (whose move path it
runs) and where the default description lives; it owns the aiming chain and its two
parameters. Pan and tilt come from the device's URDF chain
(:mod:`gimbal_driver_common.kinematics`, offsets included); the limits and the motion
refusal are checked before anything is sent, and the move then runs through the base
node's own ``~/move_to`` execution path (feedback, goal tolerance, move timeout, cancel),
so look_at and move_to behave alike. Everything here is in REP-103 joint space: the
drivers' sign conversions (Capture joint_directions, U-Camera pan) stay in the drivers.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
from rclpy.action.server import ServerGoalHandle

from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.kinematics import (
    DEFAULT_AIM_FRAME,
    AimingChain,
    KinematicsError,
    nearest_in_limits,
)
from gimbal_driver_common.ros.actions import ActionHost, MotionActions
from gimbal_msgs.action import LookAt, MoveTo


class LookAtRefused(Exception):
    """The look_at goal cannot be served; nothing was sent."""


class MoveGoalView:
    """A LookAt (or LookAtGeo) goal handle seen as a MoveTo goal handle by the base node's
    move path; feedback goes out as the action's own Feedback type."""

    def __init__(self, handle: ServerGoalHandle, request: MoveTo.Goal,
                 feedback_type: type = LookAt.Feedback) -> None:
        self._handle = handle
        self.request = request
        self._feedback_type = feedback_type

    @property
    def is_cancel_requested(self) -> bool:
        return self._handle.is_cancel_requested

    def publish_feedback(self, feedback: MoveTo.Feedback) -> None:
        self._handle.publish_feedback(self._feedback_type(positions=list(feedback.positions)))

    def succeed(self) -> None:
        self._handle.succeed()

    def abort(self) -> None:
        self._handle.abort()

    def canceled(self) -> None:
        self._handle.canceled()


class ConfiguringHost(ActionHost, Protocol):
    """An action host that declares its own parameters and logs: the aiming servers."""

    def get_logger(self) -> Any:
        """The node's logger."""

    def declare_param(self, name: str, default: object, description: str,
                      **kwargs: Any) -> Any:
        """Declare a parameter with a descriptor; its value."""


class AimNode(ConfiguringHost, Protocol):
    """What the aiming actions use of the node (:class:`~.base_node.GimbalDriverNode`)."""

    @property
    def joint_names(self) -> Sequence[str]: ...

    @property
    def limits(self) -> dict[str, JointLimits]: ...

    def motion_refusal(self, joints: Sequence[str]) -> str | None:
        """Why these joints cannot move now, or None."""


class LookAtServer:
    """Declares ``description_file``/``look_at_frame``, loads the chain, serves ~/look_at.

    The default description is ``share/<package>/urdf/<description_name>`` of the
    driver's package (``<package>.urdf`` unless the node class names another).
    """

    def __init__(self, node: AimNode, actions: MotionActions, package: str,
                 description_name: str | None = None) -> None:
        self._node = node
        self._actions = actions
        self.package = package
        self.description_name = description_name
        self.description_file: str = node.declare_param(
            'description_file', '',
            'URDF used by ~/look_at ("" = the package\'s installed urdf/ description)',
        )
        self.look_at_frame: str = node.declare_param(
            'look_at_frame', DEFAULT_AIM_FRAME,
            'link of the description whose +x axis ~/look_at points at the target',
        )
        #: the chain, read at the first aiming goal (None: not yet, or it failed)
        self._chain: AimingChain | None = None
        self._chain_read = False
        self._chain_lock = threading.Lock()
        self.aiming_error = ''
        # the description is parsed at the first aiming goal, not here (issue 47 item 2:
        # URDF parsing only when a feature needs it); here only that it is there
        try:
            path = self.description_path()
            if not Path(path).is_file():
                raise KinematicsError(f'cannot read the description {path}: no such file')
            node.get_logger().info(f'~/look_at: aims {self.look_at_frame} of {path} (read at '
                                   'the first aiming goal)')
        except KinematicsError as exc:
            self.aiming_error = str(exc)
            self._chain_read = True
            node.get_logger().warning(f'~/look_at unavailable: {exc}')
        node.create_accepting_action_server(LookAt, '~/look_at', self._execute_look_at)

    @property
    def aiming_chain(self) -> AimingChain | None:
        """The chain of the description (read once, at the first use); None when it
        cannot be read (:attr:`aiming_error` says why)."""
        with self._chain_lock:
            if not self._chain_read:
                self._chain_read = True
                try:
                    chain = self._chain = self._load_aiming_chain()
                    self._node.get_logger().info(
                        f'~/look_at: {chain.base_frame} -> {self.look_at_frame} from '
                        f'{self.description_path()} (pan {chain.pan_joint!r}, '
                        f'tilt {chain.tilt_joint!r})')
                except KinematicsError as exc:
                    self.aiming_error = str(exc)
                    self._node.get_logger().warning(f'~/look_at unavailable: {exc}')
            return self._chain

    def description_path(self) -> str:
        """The URDF file look_at uses: the parameter, else the package's installed one."""
        if self.description_file:
            return self.description_file
        package = self.package
        name = self.description_name or f'{package}.urdf'
        try:
            share = get_package_share_directory(package)
        except PackageNotFoundError as exc:
            raise KinematicsError(
                f'package {package!r} is not installed, so it has no description; '
                'set the description_file parameter'
            ) from exc
        return str(Path(share) / 'urdf' / name)

    def _load_aiming_chain(self) -> AimingChain:
        chain = AimingChain.from_file(self.description_path(), self.look_at_frame)
        for joint in (chain.pan_joint, chain.tilt_joint):
            if joint not in self._node.joint_names:
                raise KinematicsError(
                    f'the description\'s joint {joint!r} is not one of the node\'s joints '
                    f'{list(self._node.joint_names)}; give a description_file that names them'
                )
        return chain

    def plan_look_at(self, goal: LookAt.Goal) -> tuple[list[str], list[float]]:
        """Joint names and REP-103 positions that point the aim frame at the goal's target.

        Raises LookAtRefused with a message naming the frame, point or limit.
        """
        chain = self.aim_checks('look_at', goal.speed)
        frame = goal.target.header.frame_id.lstrip('/')
        if frame not in ('', chain.base_frame):
            raise LookAtRefused(
                f'target frame {goal.target.header.frame_id!r} is not the device\'s base frame '
                f'{chain.base_frame!r}: transform the point first (tf2 Buffer.transform)'
            )
        point = goal.target.point
        return self.plan_aim((point.x, point.y, point.z),
                             f'point ({point.x:.3f}, {point.y:.3f}, {point.z:.3f}) m')

    def aim_checks(self, action: str, speed: float) -> AimingChain:
        """The chain, after the checks every aiming goal passes before anything else: the
        description loaded, the joints free to move, ``speed`` valid. Raises LookAtRefused."""
        chain = self.aiming_chain
        if chain is None:
            raise LookAtRefused(f'{action} is unavailable: {self.aiming_error}')
        joints = [chain.pan_joint, chain.tilt_joint]
        refusal = self._node.motion_refusal(joints)
        if refusal:
            raise LookAtRefused(refusal)
        if not math.isfinite(speed) or speed < 0:
            raise LookAtRefused(f'speed {speed} must be >= 0 rad/s (0 = default)')
        limits = self._node.limits
        for joint in joints:
            if speed > limits[joint].velocity_max:
                raise LookAtRefused(
                    f'speed {speed:.4f} rad/s exceeds velocity_max '
                    f'{limits[joint].velocity_max:.4f} of joint {joint!r}'
                )
        return chain

    def plan_aim(self, point: tuple[float, float, float],
                 what: str) -> tuple[list[str], list[float]]:
        """Joint names and REP-103 positions that point the aim frame at ``point`` (base
        frame, m), inside the limits; LookAtRefused names ``what``, the joint and the limit.
        """
        chain = self.aiming_chain
        if chain is None:
            raise LookAtRefused(f'aiming is unavailable: {self.aiming_error}')
        joints = [chain.pan_joint, chain.tilt_joint]
        all_limits = self._node.limits
        current = self._node.current_positions()
        if not current:
            raise LookAtRefused('no joint position received yet')
        try:
            angles = chain.solve(point, current)
        except KinematicsError as exc:
            raise LookAtRefused(str(exc)) from exc
        # Pan: the turn of the solution inside the limits nearest to where pan is now (a
        # pan range wider than one turn has several); tilt has one solution.
        pan_limits = all_limits[chain.pan_joint]
        reachable: dict[str, float | None] = {
            chain.pan_joint: nearest_in_limits(
                angles[chain.pan_joint], pan_limits.position_min, pan_limits.position_max,
                current.get(chain.pan_joint, 0.0)),
            chain.tilt_joint: angles[chain.tilt_joint],
        }
        for joint, position in reachable.items():
            limits = all_limits[joint]
            if position is None or not (
                    limits.position_min - 1e-9 <= position <= limits.position_max + 1e-9):
                raise LookAtRefused(
                    f'{what} needs {joint} '
                    f'{angles[joint]:.4f} rad ({math.degrees(angles[joint]):.1f} deg), '
                    f'outside position_min {limits.position_min:.4f} .. position_max '
                    f'{limits.position_max:.4f}'
                )
        positions = []
        for joint in joints:
            position = reachable[joint]
            assert position is not None  # refused above
            limits = all_limits[joint]
            positions.append(min(max(position, limits.position_min), limits.position_max))
        return joints, positions

    def _execute_look_at(self, goal_handle: ServerGoalHandle) -> LookAt.Result:
        result = LookAt.Result()
        try:
            joints, positions = self.plan_look_at(goal_handle.request)
        except LookAtRefused as exc:
            return self.refuse_aim(goal_handle, result, 'look_at', exc)
        return self.move_aim(goal_handle, result, joints, positions, LookAt.Feedback)

    def refuse_aim(self, goal_handle: ServerGoalHandle, result: Any, action: str,
                   reason: Exception) -> Any:
        """Abort an aiming goal that sent nothing: the result names the joints, where they
        are and why."""
        goal_handle.abort()
        chain = self.aiming_chain
        result.joint_names = [chain.pan_joint, chain.tilt_joint] if chain else []
        current = self._node.current_positions()
        result.positions = [current.get(j, math.nan) for j in result.joint_names]
        result.success, result.message = False, f'{action} refused, nothing sent: {reason}'
        return result

    def move_aim(self, goal_handle: ServerGoalHandle, result: Any, joints: list[str],
                 positions: list[float], feedback_type: type) -> Any:
        """Run a planned aim exactly like ~/move_to (feedback, tolerance, timeout, cancel)."""
        speed = goal_handle.request.speed
        move = MoveTo.Goal(
            joint_names=joints, positions=positions,
            velocities=[speed] * len(joints) if speed > 0 else [], relative=False,
        )
        moved = self._actions.execute_move(MoveGoalView(goal_handle, move, feedback_type))
        result.success = moved.success
        result.message = moved.message
        result.positions = list(moved.positions)
        result.joint_names = joints
        return result
