"""The MoveTo and Home actions on the policies, the guarded device procedures as Home
actions, and a lifecycle guard; mixed into the node."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from typing import Any

from lifecycle_msgs.srv import ChangeState
from rclpy.action import ActionServer, GoalResponse
from rclpy.lifecycle import LifecycleNode

from gimbal_driver_common.device import Device, DeviceProcedure
from gimbal_driver_common.errors import DeviceRefused, GimbalError
from gimbal_driver_common.policies import HomingSuperseded
from gimbal_msgs.action import Home, MoveTo

#: builds a device procedure from the adapter and the goal's joint names
ProcedureFactory = Callable[[Device, Sequence[str]], DeviceProcedure]


class OpenGoals:
    """The goals the node's action servers accepted and have not ended yet.

    A node that shuts down halts the axes, which ends every running goal; its executor must
    then still run until rclpy has run each execute callback to its end, so that every
    client hears how its goal ended instead of waiting for a server that is gone. A goal
    that comes once the node is going away is rejected: that answer goes out at once.
    """

    def __init__(self) -> None:
        self._open = 0
        self._closed = False
        self._changed = threading.Condition()

    def admit(self, _goal: object) -> GoalResponse:
        """The ``goal_callback``: an accepted goal counts as open from here on (before
        rclpy answers the client), a goal after :meth:`close` is rejected."""
        with self._changed:
            if self._closed:
                return GoalResponse.REJECT
            self._open += 1
            return GoalResponse.ACCEPT

    def close(self) -> None:
        """The node is going away: reject new goals."""
        with self._changed:
            self._closed = True

    def tracked(self, execute: Callable[..., Any]) -> Callable[..., Any]:
        """``execute`` that counts its goal as ended when it returns or raises."""
        def run(goal_handle):
            try:
                return execute(goal_handle)
            finally:
                with self._changed:
                    self._open -= 1
                    self._changed.notify_all()

        return run

    @property
    def count(self) -> int:
        with self._changed:
            return self._open

    def wait_ended(self, timeout: float) -> bool:
        """True once no goal is open; False if some still are after ``timeout`` seconds."""
        with self._changed:
            return self._changed.wait_for(lambda: self._open == 0, timeout)


def end_goal(goal_handle, result, cancelled: bool):
    """End an action goal by its result: canceled (never a success), succeeded or
    aborted; returns ``result``."""
    if cancelled:
        result.success = False
        goal_handle.canceled()
    elif result.success:
        goal_handle.succeed()
    else:
        goal_handle.abort()
    return result


def state_reporter(goal_handle) -> Callable[[str], None]:
    """Publish a text as the Home feedback ``state`` of ``goal_handle``."""
    feedback = Home.Feedback()

    def report(state: str) -> None:
        feedback.state = state
        goal_handle.publish_feedback(feedback)

    return report


class MotionActions:
    """``~/move_to``, ``~/home`` and the guarded procedures' execute callbacks (the node
    provides controller, motion and procedures)."""

    def _execute_move(self, goal_handle):
        goal = goal_handle.request
        result = MoveTo.Result()
        try:
            if self.motion is None:
                raise DeviceRefused(self.command_refusal())
            targets = self.motion.start_move(goal.joint_names, goal.positions, goal.velocities,
                                             goal.relative)
        except GimbalError as exc:
            goal_handle.abort()
            result.success, result.message = False, f'move refused, nothing sent: {exc}'
            current = self.current_positions()
            result.positions = [current.get(n, math.nan) for n in goal.joint_names]
            return result
        return self._finish_move(goal_handle, targets, goal.tolerance)

    def _finish_move(self, goal_handle, targets: dict[str, float],
                     tolerance: float) -> MoveTo.Result:
        """Wait for a started move (ours or one the device runs itself, e.g. its own
        target pointing): feedback, then reached / cancelled / stopped / timeout."""
        result = MoveTo.Result()
        feedback = MoveTo.Feedback()

        def publish(positions: list[float]) -> None:
            feedback.positions = positions
            goal_handle.publish_feedback(feedback)

        outcome = self.motion.wait_move(
            targets, tolerance, lambda: goal_handle.is_cancel_requested, publish)
        result.positions, result.success, result.message = (
            outcome.positions, outcome.success, outcome.message)
        return end_goal(goal_handle, result, cancelled=outcome.state == 'cancelled')

    def _execute_home(self, goal_handle):
        joints = list(goal_handle.request.joint_names) or list(self.joint_names)
        result = Home.Result()
        report = state_reporter(goal_handle)
        superseded = False
        try:
            if self.motion is None:
                raise DeviceRefused(self.command_refusal())
            self.controller.require()
            result.message = self.motion.home(joints, report,
                                              lambda: goal_handle.is_cancel_requested)
            result.success = True
        except HomingSuperseded as exc:
            superseded, result.success, result.message = True, False, str(exc)
        except GimbalError as exc:
            result.success, result.message = False, str(exc)
        cancelled = goal_handle.is_cancel_requested and not superseded
        if cancelled:
            self.controller.stop_joints(joints)
            result.message = 'homing cancelled'
        return end_goal(goal_handle, result, cancelled)

    def create_procedure_action(self, name: str, make: ProcedureFactory) -> ActionServer:
        """A Home action that runs ``make(device, goal joint names)`` through the guarded
        procedure policy (``guarded.GuardedProcedures``); a cancel request wakes its wait."""
        def wake() -> None:
            if self.procedures is not None:
                self.procedures.wake()

        return self.create_accepting_action_server(
            Home, name, lambda goal_handle: self._execute_procedure(goal_handle, make),
            on_cancel=wake)

    def _execute_procedure(self, goal_handle, make: ProcedureFactory) -> Home.Result:
        result = Home.Result()
        joints = list(goal_handle.request.joint_names)
        try:
            if self.procedures is None:
                raise DeviceRefused(self.command_refusal())
            result.message = self.procedures.run(
                lambda: make(self.controller.device, joints), state_reporter(goal_handle),
                lambda: goal_handle.is_cancel_requested)
            result.success = True
        except GimbalError as exc:
            result.success, result.message = False, str(exc)
        return end_goal(goal_handle, result, goal_handle.is_cancel_requested)


def guard_change_state_service(node: LifecycleNode, state: Callable[[], str]) -> None:
    """Answer an impossible lifecycle transition with success=false instead of dying.

    rclpy's ``~/change_state`` lets the error of a transition the current state lacks
    escape into the executor, which ends the spin (found by `make soak`). The service is
    found among the node's public ``services`` (the one of type ChangeState); ``state()``
    names the current state for the warning.
    """
    for service in node.services:
        if service.srv_type is ChangeState:
            break
    else:
        return
    handler = service.callback

    def guarded(request: ChangeState.Request, response: ChangeState.Response):
        try:
            return handler(request, response)
        except Exception as exc:  # noqa: BLE001 - rclpy's RCLError is not public; any refusal
            node.get_logger().warning(
                f'lifecycle transition {request.transition.label or request.transition.id!r}'
                f' refused in state {state()!r}: {exc}')
            response.success = False
            return response

    service.callback = guarded
