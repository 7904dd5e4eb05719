"""What the parts of a driver node cost in memory (issue 47 item 2; bench/README.md, "What a
node imports, and what it costs").

``python bench/memory_parts.py imports MODULE...``: in this process, first everything a
running bare rclpy node loads (``reference_publisher.py``'s node: rclpy, a node, a
JointState publisher and timer, one spin), then each MODULE in turn; prints the PSS and
anonymous PSS each import added (``/proc/self/smaps_rollup``, after a collection). A row
includes what the module imports that was not loaded yet.

``python bench/memory_parts.py endpoints [--lifecycle]``: PSS added by a Node (a
LifecycleNode with ``--lifecycle``: the difference of the two runs is what the lifecycle
adds), a publisher, services and action servers, each created in turn.

Not part of ``make bench``; run it niced, alone, in a ROS domain of its own
(``scripts/ros_env.sh`` picks one). Steps under about 0.3 MB are at the allocator's
granularity (obmalloc arenas, pages).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import sys
import time
from pathlib import Path


def pss_kb() -> tuple[int, int]:
    """(PSS, anonymous PSS) of this process in kB."""
    values: dict[str, int] = {}
    for line in Path('/proc/self/smaps_rollup').read_text().splitlines():
        key, *rest = line.split()
        if key in ('Pss:', 'Pss_Anon:'):
            values[key] = int(rest[0])
    return values['Pss:'], values['Pss_Anon:']


class Steps:
    """Prints what each step added to the process's PSS."""

    def __init__(self) -> None:
        self.last = pss_kb()

    def mark(self, label: str, settle_s: float = 0.0) -> None:
        if settle_s:
            time.sleep(settle_s)  # DDS threads allocate right after an entity is created
        gc.collect()
        now = pss_kb()
        print(f'{now[0] / 1024:7.1f} MB  {(now[0] - self.last[0]) / 1024:+6.2f} MB  '
              f'anon {(now[1] - self.last[1]) / 1024:+6.2f} MB  {label}', flush=True)
        self.last = now


def bare_node_modules() -> None:
    """Load what a running bare node has loaded, by being one for a moment."""
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    rclpy.init()
    node = rclpy.create_node('memory_parts_bare')
    publisher = node.create_publisher(JointState, 'memory_parts_states',
                                      QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    node.create_timer(0.02, lambda: publisher.publish(JointState(name=['pan', 'tilt'])))
    rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.try_shutdown()


def imports(modules: list[str]) -> None:
    steps = Steps()
    bare_node_modules()
    steps.mark(f'what a bare node loads ({len(sys.modules)} modules)')
    for name in modules:
        importlib.import_module(name)
        steps.mark(name)


def endpoints(lifecycle: bool) -> None:
    steps = Steps()
    import rclpy
    from rclpy.action import ActionServer
    from rclpy.lifecycle import LifecycleNode
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger

    from gimbal_msgs.action import MoveTo
    steps.mark('imports (rclpy, lifecycle, action, sensor_msgs, std_srvs, gimbal_msgs)')
    rclpy.init()
    node = LifecycleNode('memory_parts_node') if lifecycle else rclpy.create_node(
        'memory_parts_node')
    steps.mark(f'a {type(node).__name__} (and the participant)', 0.5)
    node.create_publisher(JointState, 'memory_parts_states', 10)
    steps.mark('the first publisher', 0.5)
    for index in range(10):
        node.create_service(Trigger, f'~/service_{index}', lambda _request, response: response)
    steps.mark('10 Trigger services', 0.5)
    servers = [ActionServer(node, MoveTo, f'~/action_{index}', lambda _goal: MoveTo.Result())
               for index in range(4)]
    steps.mark('4 MoveTo action servers', 0.5)
    servers += [ActionServer(node, MoveTo, f'~/more_{index}', lambda _goal: MoveTo.Result())
                for index in range(4)]
    steps.mark('4 more MoveTo action servers', 0.5)
    for index in range(5):
        node.create_publisher(JointState, f'memory_parts_more_{index}', 10)
    steps.mark('5 more publishers', 0.5)
    for server in servers:
        server.destroy()
    node.destroy_node()
    rclpy.try_shutdown()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest='command', required=True)
    commands.add_parser('imports').add_argument('modules', nargs='+')
    commands.add_parser('endpoints').add_argument('--lifecycle', action='store_true')
    args = parser.parse_args()
    if args.command == 'imports':
        imports(args.modules)
    else:
        endpoints(args.lifecycle)
    return 0


if __name__ == '__main__':
    sys.exit(main())
