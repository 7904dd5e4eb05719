"""Peer process for test_gimbal_msgs_cross_process: echoes every gimbal_msgs type back over
ROS."""

from __future__ import annotations

import contextlib
import importlib
import sys

import rclpy
from rclpy.action import ActionServer
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor


def interface_names(kind: str) -> list[str]:
    """The types rosidl generated in ``gimbal_msgs.<kind>`` (msg, srv or action): every one
    of them, with no list here to keep in step with CMakeLists.txt."""
    module = importlib.import_module(f'gimbal_msgs.{kind}')
    return sorted(name for name in dir(module)  # not the generated Foo_Request etc.
                  if name[:1].isupper() and '_' not in name
                  and isinstance(getattr(module, name), type))


MESSAGES, SERVICES, ACTIONS = (interface_names(kind) for kind in ('msg', 'srv', 'action'))


def main() -> int:
    rclpy.init()
    node = rclpy.create_node('gimbal_msgs_peer')
    msg_mod = importlib.import_module('gimbal_msgs.msg')
    srv_mod = importlib.import_module('gimbal_msgs.srv')
    action_mod = importlib.import_module('gimbal_msgs.action')
    keep = []
    for name in MESSAGES:
        kind = getattr(msg_mod, name)
        pub = node.create_publisher(kind, f'echo_out/{name}', 10)
        keep.append(node.create_subscription(kind, f'echo_in/{name}', pub.publish, 10))
    for name in SERVICES:
        kind = getattr(srv_mod, name)

        def answer(request, response, name=name):
            response.success = True
            response.message = f'{name} served'
            return response

        keep.append(node.create_service(kind, f'srv/{name}', answer))
    for name in ACTIONS:
        kind = getattr(action_mod, name)

        def execute(goal_handle, kind=kind):
            result = kind.Result()
            result.success = True
            result.message = f'{kind.__name__} done'
            feedback = kind.Feedback()
            goal_handle.publish_feedback(feedback)
            if hasattr(goal_handle.request, 'positions'):
                result.positions = list(goal_handle.request.positions)
            if hasattr(goal_handle.request, 'target'):  # LookAt: echo the point back
                point = goal_handle.request.target.point
                result.positions = [point.x, point.y, point.z]
            if hasattr(goal_handle.request, 'latitude'):  # LookAtGeo: echo the place back
                request = goal_handle.request
                result.positions = [request.latitude, request.longitude, request.altitude]
            goal_handle.succeed()
            return result

        keep.append(ActionServer(node, kind, f'action/{name}', execute))
    print('peer ready', flush=True)
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        executor.spin()
    return 0


if __name__ == '__main__':
    sys.exit(main())
