"""Reference for the command stream: a bare rclpy subscriber writing one byte per message.

It subscribes to ``reference_command`` (the stream publisher's copy of each ``joint_command``,
half a period later) like a driver node (keep-last 1) and, for each message,
writes one byte (the command index from ``header.frame_id``, modulo 256) to a TCP socket on
127.0.0.1 with Nagle off: publish -> byte on the socket, the path a driver takes without
any driver code in it.

Usage: reference_subscriber.py PORT
"""

from __future__ import annotations

import socket
import sys

import rclpy
from rclpy.executors import ExternalShutdownException
from sensor_msgs.msg import JointState


def main() -> int:
    port = int(sys.argv[1])
    link = socket.create_connection(('127.0.0.1', port))
    link.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    rclpy.init()
    node = rclpy.create_node('bench_reference_subscriber')

    def on_command(msg: JointState) -> None:
        link.sendall(bytes([int(msg.header.frame_id or 0) & 0xFF]))

    node.create_subscription(JointState, 'reference_command', on_command, 1)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        link.close()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
