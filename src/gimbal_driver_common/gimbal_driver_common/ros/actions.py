"""The MoveTo and Home actions on the policies, the guarded device procedures as Home
actions, and a lifecycle guard. :class:`MotionActions` is a part of the node (its
``motion_actions`` attribute), handed the node's public side (:class:`ActionNode`)."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from lifecycle_msgs.srv import ChangeState
from rclpy.action import ActionServer, GoalResponse
from rclpy.lifecycle import LifecycleNode

from gimbal_driver_common.controller import GimbalController
from gimbal_driver_common.device import Device, DeviceProcedure
from gimbal_driver_common.errors import DeviceRefused, GimbalError
from gimbal_driver_common.guarded import GuardedProcedures
from gimbal_driver_common.policies import HomingSuperseded, Motion
from gimbal_msgs.action import Home, MoveTo

#: builds a device procedure from the adapter and the goal's joint names
ProcedureFactory = Callable[[Device, Sequence[str]], DeviceProcedure]


class OpenGoals:
    """The goals the node's action servers accepted and have not ended yet.

    A node that shuts down halts the axes, which ends every running goal; its executor must
    then still run until rclpy has run each execute callback to its end, so that every
    client hears how its goal ended instead of waiting for a server that is gone. A goal
    that comes once the node is going away is rejected: that answer goes out at once.

    A client asks for a goal's result when it hears the goal accepted, one round trip
    after the acceptance went out; a goal that the shutdown ends right after its acceptance
    may have that request still on its way. :meth:`result_request_due` says how long to
    keep answering for it.
    """

    #: seconds after the last acceptance during which its client's result request may
    #: still be on its way (a round trip through DDS on a loaded host, with room)
    RESULT_REQUEST_S = 1.0

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._open = 0
        self._closed = False
        self._changed = threading.Condition()
        self._clock = clock
        self._last_admitted: float | None = None

    def admit(self, _goal: object) -> GoalResponse:
        """The ``goal_callback``: an accepted goal counts as open from here on (before
        rclpy answers the client), a goal after :meth:`close` is rejected."""
        with self._changed:
            if self._closed:
                return GoalResponse.REJECT
            self._open += 1
            self._last_admitted = self._clock()
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

    def result_request_due(self) -> float:
        """Seconds until no result request of an accepted goal can still be on its way (0:
        none accepted, or the last long enough ago)."""
        with self._changed:
            if self._last_admitted is None:
                return 0.0
            return max(0.0, self._last_admitted + self.RESULT_REQUEST_S - self._clock())

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


class ActionHost(Protocol):
    """What every action part (motion, look_at, look_at_geo) uses of the node
    (:class:`~.base_node.GimbalDriverNode`): its positions and its action servers."""

    def current_positions(self) -> dict[str, float]:
        """The latest joint positions (empty before configure)."""

    def create_accepting_action_server(self, action_type: type, name: str,
                                       execute: Callable[..., Any],
                                       on_cancel: Callable[[], None] = ...,
                                       ) -> ActionServer:
        """An action server that accepts every goal; ``execute`` refuses by aborting."""


class ActionNode(ActionHost, Protocol):
    """What the motion actions use of the node (:class:`~.base_node.GimbalDriverNode`):
    what configure built (None before), its joints and refusals, its action servers."""

    @property
    def controller(self) -> GimbalController | None: ...

    @property
    def motion(self) -> Motion | None: ...

    @property
    def procedures(self) -> GuardedProcedures | None: ...

    @property
    def joint_names(self) -> Sequence[str]: ...

    def command_refusal(self) -> str | None:
        """Why commands cannot be served now (inactive, disconnected), or None."""


class MotionActions:
    """``~/move_to``, ``~/home`` and the guarded procedures' execute callbacks."""

    def __init__(self, node: ActionNode) -> None:
        self._node = node

    def _motion(self) -> Motion:
        """The node's motion policies; refused (the node's reason) before configure."""
        motion = self._node.motion
        if motion is None:
            raise DeviceRefused(self._node.command_refusal())
        return motion

    def execute_move(self, goal_handle):
        """The ``~/move_to`` execute callback (also ``~/look_at``'s move path)."""
        goal = goal_handle.request
        result = MoveTo.Result()
        try:
            targets = self._motion().start_move(goal.joint_names, goal.positions,
                                                goal.velocities, goal.relative)
        except GimbalError as exc:
            goal_handle.abort()
            result.success, result.message = False, f'move refused, nothing sent: {exc}'
            current = self._node.current_positions()
            result.positions = [current.get(n, math.nan) for n in goal.joint_names]
            return result
        return self.finish_move(goal_handle, targets, goal.tolerance)

    def finish_move(self, goal_handle, targets: dict[str, float],
                    tolerance: float) -> MoveTo.Result:
        """Wait for a started move (ours or one the device runs itself, e.g. its own
        target pointing): feedback, then reached / cancelled / stopped / timeout."""
        result = MoveTo.Result()
        feedback = MoveTo.Feedback()

        def publish(positions: list[float]) -> None:
            feedback.positions = positions
            goal_handle.publish_feedback(feedback)

        outcome = self._motion().wait_move(
            targets, tolerance, lambda: goal_handle.is_cancel_requested, publish)
        result.positions, result.success, result.message = (
            outcome.positions, outcome.success, outcome.message)
        return end_goal(goal_handle, result, cancelled=outcome.state == 'cancelled')

    def execute_home(self, goal_handle):
        """The ``~/home`` execute callback."""
        joints = list(goal_handle.request.joint_names) or list(self._node.joint_names)
        result = Home.Result()
        report = state_reporter(goal_handle)
        superseded = False
        controller = self._node.controller
        try:
            motion = self._motion()
            assert controller is not None  # configure builds both
            controller.require()
            result.message = motion.home(joints, report,
                                         lambda: goal_handle.is_cancel_requested)
            result.success = True
        except HomingSuperseded as exc:
            superseded, result.success, result.message = True, False, str(exc)
        except GimbalError as exc:
            result.success, result.message = False, str(exc)
        cancelled = goal_handle.is_cancel_requested and not superseded
        if cancelled and controller is not None:
            controller.stop_joints(joints)
            result.message = 'homing cancelled'
        return end_goal(goal_handle, result, cancelled)

    def create_procedure_action(self, name: str, make: ProcedureFactory) -> ActionServer:
        """A Home action that runs ``make(device, goal joint names)`` through the guarded
        procedure policy (``guarded.GuardedProcedures``); a cancel request wakes its wait."""
        def wake() -> None:
            procedures = self._node.procedures
            if procedures is not None:
                procedures.wake()

        return self._node.create_accepting_action_server(
            Home, name, lambda goal_handle: self._execute_procedure(goal_handle, make),
            on_cancel=wake)

    def _execute_procedure(self, goal_handle, make: ProcedureFactory) -> Home.Result:
        result = Home.Result()
        joints = list(goal_handle.request.joint_names)
        node = self._node
        try:
            procedures, controller = node.procedures, node.controller
            if procedures is None or controller is None:
                raise DeviceRefused(node.command_refusal())
            device = controller.device
            result.message = procedures.run(
                lambda: make(device, joints), state_reporter(goal_handle),
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
