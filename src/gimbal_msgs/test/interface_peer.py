"""Peer process for test_interfaces: echoes every gimbal_msgs type back over ROS."""

from __future__ import annotations

import contextlib
import importlib
import sys

import rclpy
from rclpy.action import ActionServer
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor

MESSAGES = ['AxisState', 'GimbalStatus', 'Preset', 'PlaybackStatus', 'BezierSegment',
            'AxisTrajectory']
SERVICES = ['SetPreset', 'GotoPreset', 'ListPresets', 'ClearPreset', 'StartScan',
            'LoadTrajectory', 'SetMode', 'DeviceCommand', 'Calibrate']
ACTIONS = ['MoveTo', 'Home', 'LookAt', 'LookAtGeo']


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
