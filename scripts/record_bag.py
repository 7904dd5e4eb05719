"""Record every topic of this ROS domain to an MCAP file (a small `ros2 bag record -a`).

There is no rosbag2 on PyPI, so this subscribes with raw (CDR) callbacks and
writes ROS 2 MCAP channels (schema encoding ``ros2msg``, message encoding
``cdr``) that Foxglove Studio and ``ros2 bag`` open. Message definitions are
assembled from the ``.msg`` files of the installed packages. Stops on SIGINT.

    python scripts/record_bag.py OUTPUT.mcap
"""

from __future__ import annotations

import importlib
import os
import re
import signal
import sys
import threading
import time
from pathlib import Path

import rclpy
import rclpy.signals
from mcap.writer import Writer
from rclpy.qos import QoSProfile, ReliabilityPolicy

BUILTINS = {
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring', 'time', 'duration',
}
SEPARATOR = '=' * 80


def get_message(type_name: str) -> type:
    """The Python class of ``pkg/msg/Type`` (rosidl_runtime_py is not on PyPI)."""
    package, kind, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


def find_msg_file(package: str, name: str) -> Path:
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        candidate = Path(prefix, 'share', package, 'msg', f'{name}.msg')
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f'{package}/msg/{name}.msg not found in AMENT_PREFIX_PATH')


FIELD = re.compile(r'^(?P<type>[A-Za-z0-9_/]+)(?:<=\d+)?(?:\[[^\]]*\])?\s+\w+(?P<rest>.*)$')


def dependencies(package: str, text: str) -> list[str]:
    """Complex field types of a .msg text, as pkg/Type (constants and builtins skipped)."""
    found = []
    for raw in text.splitlines():
        line = raw.split('#', 1)[0].strip()
        match = FIELD.match(line)
        if match is None or match.group('rest').lstrip().startswith('='):
            continue
        field_type = match.group('type')
        if field_type in BUILTINS:
            continue
        if field_type == 'Header':
            field_type = 'std_msgs/Header'
        if '/' not in field_type:
            field_type = f'{package}/{field_type}'
        found.append(field_type.replace('/msg/', '/'))
    return found


def message_definition(type_name: str) -> str:
    """The concatenated definition ROS 2 MCAP expects: the type, then each dependency once."""
    package, _, name = type_name.replace('/msg/', '/').partition('/')
    root = find_msg_file(package, name).read_text(encoding='utf-8')
    parts = [root]
    seen = set()
    queue = dependencies(package, root)
    while queue:
        dep = queue.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        dep_package, _, dep_name = dep.partition('/')
        text = find_msg_file(dep_package, dep_name).read_text(encoding='utf-8')
        parts.append(f'{SEPARATOR}\nMSG: {dep}\n{text}')
        queue += dependencies(dep_package, text)
    return '\n'.join(parts)


class Recorder:
    def __init__(self, path: str) -> None:
        self.node = rclpy.create_node('gimbal_bag_recorder')
        self._file = open(path, 'wb')  # noqa: SIM115 - closed in close()
        self.writer = Writer(self._file)
        self.writer.start(profile='ros2', library='gimbal-suite record_bag')
        self.channels: dict[str, int] = {}
        self.skipped: set[str] = set()
        self.schemas: dict[str, int] = {}
        self.lock = threading.Lock()
        self.count = 0
        self.node.create_timer(0.5, self.discover)
        self.discover()

    def discover(self) -> None:
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self.channels or topic in self.skipped or not types:
                continue
            if '/_action/' in topic or topic.startswith('/_'):
                self.skipped.add(topic)  # hidden topics, as `ros2 bag record -a` skips them
                continue
            type_name = types[0]
            try:
                msg_class = get_message(type_name)
                definition = message_definition(type_name)
            except (AttributeError, ModuleNotFoundError, ValueError, FileNotFoundError) as exc:
                self.node.get_logger().warning(f'not recording {topic}: {exc}')
                self.skipped.add(topic)
                continue
            schema_name = type_name.replace('/msg/', '/')
            with self.lock:
                if schema_name not in self.schemas:
                    self.schemas[schema_name] = self.writer.register_schema(
                        schema_name, 'ros2msg', definition.encode())
                channel = self.writer.register_channel(
                    topic, 'cdr', self.schemas[schema_name])
                self.channels[topic] = channel
            qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
            self.node.create_subscription(
                msg_class, topic, lambda data, c=channel: self.write(c, data), qos, raw=True)

    def write(self, channel: int, data: bytes) -> None:
        now = time.time_ns()
        with self.lock:
            self.writer.add_message(channel, log_time=now, data=data, publish_time=now,
                                    sequence=self.count)
            self.count += 1

    def close(self) -> None:
        with self.lock:
            self.writer.finish()
            self._file.close()


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())  # before init: an early Ctrl-C
    signal.signal(signal.SIGTERM, lambda *_: stop.set())  # still closes a valid file
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    recorder = Recorder(sys.argv[1])
    while not stop.is_set():
        rclpy.spin_once(recorder.node, timeout_sec=0.1)
    recorder.close()
    print(f'record_bag: {recorder.count} messages on {len(recorder.channels)} topics '
          f'-> {sys.argv[1]}', flush=True)
    recorder.node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
