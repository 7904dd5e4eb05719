"""Reference for the benchmarks: a bare rclpy JointState publisher at a fixed rate."""

from __future__ import annotations

import sys
import time

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState


def main() -> int:
    rate_hz = float(sys.argv[1]) if len(sys.argv) > 1 else 100.0
    rclpy.init()
    node = rclpy.create_node('reference_publisher')
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    publisher = node.create_publisher(JointState, 'reference_joint_states', qos)
    msg = JointState(name=['pan', 'tilt'], position=[0.0, 0.0], velocity=[0.0, 0.0])

    def tick() -> None:
        now = time.time()
        msg.header.stamp.sec = int(now)
        msg.header.stamp.nanosec = int((now - int(now)) * 1e9)
        msg.position[0] = now % 1.0
        publisher.publish(msg)

    node.create_timer(1.0 / rate_hz, tick)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
