"""A user's closed loop: publishes ``joint_command`` at a steady timer-paced rate.

Command ``i`` moves ``joint`` to ``base + step * i`` (a new, distinguishable target every
command) and carries ``i`` in ``header.frame_id``. The same message goes to the bare-rclpy
reference on ``reference_command`` half a period later: interleaved, the driver node and the
reference subscriber never wake on the same message and race each other for the cores (on
2 cores that race decided which of the two p50s came out slow). The publisher waits until
``subscribers`` subscriptions on ``joint_command`` (the driver node) and one on
``reference_command`` have matched, then publishes ``count`` commands on each from one rclpy
timer at twice the rate and writes the wall-clock time of each ``publish()`` call as JSON
(``{"publish_times": [...], "reference_publish_times": [...]}``) to ``output``.

Usage: stream_publisher.py RATE_HZ COUNT JOINT BASE STEP SUBSCRIBERS OUTPUT
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import rclpy
from sensor_msgs.msg import JointState

#: the publisher sees a subscriber before that subscriber has matched the publisher; a
#: message sent in between is lost (the same settling RosTestClient.publish allows)
DISCOVERY_SETTLE_S = 1.0


def main() -> int:
    rate_hz, count = float(sys.argv[1]), int(sys.argv[2])
    joint, base, step = sys.argv[3], float(sys.argv[4]), float(sys.argv[5])
    subscribers, output = int(sys.argv[6]), Path(sys.argv[7])
    rclpy.init()
    node = rclpy.create_node('bench_stream_publisher')
    publisher = node.create_publisher(JointState, 'joint_command', 10)
    reference = node.create_publisher(JointState, 'reference_command', 10)
    deadline = time.monotonic() + 30.0
    while (publisher.get_subscription_count() < subscribers
           or reference.get_subscription_count() < 1):
        if time.monotonic() > deadline:
            graph = [f'{info.node_namespace}/{info.node_name}'
                     for info in node.get_subscriptions_info_by_topic('/joint_command')]
            graph.append(f'nodes: {node.get_node_names()}')
            print(f'stream_publisher: {publisher.get_subscription_count()} of {subscribers} '
                  f'subscribers matched after 30 s (graph: {graph})', file=sys.stderr)
            return 1
        time.sleep(0.05)
    time.sleep(DISCOVERY_SETTLE_S)
    publish_times: list[float] = []
    reference_times: list[float] = []

    def tick() -> None:
        # even ticks: the driver's command; odd ticks: the same one to the reference
        to_driver = len(publish_times) == len(reference_times)
        times = publish_times if to_driver else reference_times
        index = len(times)
        if index >= count:
            return
        msg = JointState(name=[joint], position=[base + step * index])
        msg.header.frame_id = str(index)
        now = time.time()
        msg.header.stamp.sec = int(now)
        msg.header.stamp.nanosec = int((now - int(now)) * 1e9)
        times.append(now)
        (publisher if to_driver else reference).publish(msg)

    node.create_timer(0.5 / rate_hz, tick)
    while rclpy.ok() and len(reference_times) < count:
        rclpy.spin_once(node, timeout_sec=0.1)
    # written whole, then renamed: the bench reads it as soon as the name exists
    partial = output.with_name(output.name + '.partial')
    partial.write_text(json.dumps({'rate_hz': rate_hz, 'publish_times': publish_times,
                                  'reference_publish_times': reference_times}))
    partial.replace(output)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
