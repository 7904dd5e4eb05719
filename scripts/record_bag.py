"""Record topics of this ROS domain to a rosbag2 bag, as ``ros2 bag record -s mcap`` does.

The bag is a directory with ``metadata.yaml`` and MCAP storage, written by the
``rosbags`` library (rosbag2 metadata version 9, the one Jazzy writes): type
names as ``pkg/msg/Type``, each type's full message definition and
RIHS01 type hash, and the QoS every publisher of a topic offered. Types
``rosbags`` does not ship (``gimbal_msgs``, any workspace package) are
registered from the ``.msg`` files found in ``AMENT_PREFIX_PATH``.

A topic is recorded once it has a publisher (its offered QoS is known then);
the subscription adapts to the offers as ``ros2 bag record`` does. Ctrl-C (or
SIGTERM, or ``--duration``) ends the recording and closes the bag cleanly.

    python scripts/record_bag.py -o OUTPUT_DIR [-d SECONDS] [-a | TOPIC ...]
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import rclpy
import rclpy.signals
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.topic_endpoint_info import TopicEndpointInfo
from rosbags.interfaces import (
    Connection,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype
from rosbags.typesys.store import Typestore

# The rosbag2 metadata version ROS 2 Jazzy writes (rosbag2 0.26: BagMetadata::version = 9).
METADATA_VERSION = 9
# Hidden topics (a path part starting with '_', e.g. actions' /_action/ topics) are left
# out, as `ros2 bag record` leaves them out without --include-hidden-topics.
HIDDEN = re.compile(r'(^|/)_')


def message_class(type_name: str) -> type:
    """The Python class of ``pkg/msg/Type`` (what rosidl_runtime_py.get_message does)."""
    package, kind, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


class WorkspaceTypes:
    """A rosbags type store with Jazzy's standard types plus every package found in
    ``AMENT_PREFIX_PATH`` whose message types rosbags does not ship."""

    def __init__(self, prefixes: Iterable[str] | None = None) -> None:
        self.store: Typestore = get_typestore(Stores.ROS2_JAZZY)
        if prefixes is None:
            prefixes = os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
        self.prefixes = [Path(p) for p in prefixes if p]

    def msg_files(self, package: str) -> list[Path]:
        for prefix in self.prefixes:
            folder = prefix / 'share' / package / 'msg'
            if folder.is_dir():
                return sorted(folder.glob('*.msg'))
        return []

    def ensure(self, type_name: str) -> None:
        """Make ``type_name`` (and every type it refers to) known to the store."""
        pending = [type_name]
        while pending:
            name = pending.pop()
            if name in self.store.fielddefs:
                continue
            package = name.split('/', 1)[0]
            files = self.msg_files(package)
            if not files:
                raise LookupError(f'{name}: no share/{package}/msg/*.msg in AMENT_PREFIX_PATH')
            types: dict[str, Any] = {}
            for path in files:
                types.update(get_types_from_msg(path.read_text(encoding='utf-8'),
                                                f'{package}/msg/{path.stem}'))
            if name not in types:
                raise LookupError(f'{name}: not among the .msg files of {package}')
            # Types of other packages they refer to must be registered first.
            missing = {ref for _, fields in types.values() for _, desc in fields
                       for ref in referenced_types(desc)
                       if ref not in types and ref not in self.store.fielddefs}
            if missing:
                pending += [name, *missing]
                continue
            self.store.register(types)


def referenced_types(desc: tuple[Any, Any]) -> list[str]:
    """Message type names a rosbags field descriptor refers to."""
    kind, detail = desc
    if kind == Nodetype.NAME:
        return [detail]
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return referenced_types(detail[0])
    return []


def qos_time(duration: Duration) -> QosTime:
    sec, nsec = divmod(duration.nanoseconds, 1_000_000_000)
    return QosTime(sec, nsec)


def offered_qos(profile: QoSProfile) -> Qos:
    """A publisher's QoS as rosbag2 stores it in offered_qos_profiles."""
    return Qos(
        history=QosHistory[HistoryPolicy(profile.history).name],
        depth=profile.depth,
        reliability=QosReliability[ReliabilityPolicy(profile.reliability).name],
        durability=QosDurability[DurabilityPolicy(profile.durability).name],
        deadline=qos_time(profile.deadline),
        lifespan=qos_time(profile.lifespan),
        liveliness=QosLiveliness[LivelinessPolicy(profile.liveliness).name],
        liveliness_lease_duration=qos_time(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=profile.avoid_ros_namespace_conventions,
    )


def subscription_qos(offers: Sequence[QoSProfile]) -> QoSProfile:
    """Reliable / transient-local only when every publisher offers it (rosbag2's rule),
    so the recorder matches every publisher and still gets the latched messages."""
    reliable = all(o.reliability == ReliabilityPolicy.RELIABLE for o in offers)
    latched = all(o.durability == DurabilityPolicy.TRANSIENT_LOCAL for o in offers)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=100,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class BagRecorder:
    """Subscribes (raw CDR) to the chosen topics as they appear and writes each message
    with its receive time. Callbacks run on the one thread that spins ``node``."""

    def __init__(self, node: Node, output: Path, topics: Sequence[str] = (),
                 include_hidden: bool = False) -> None:
        self.node = node
        self.wanted = set(topics)
        self.include_hidden = include_hidden
        self.types = WorkspaceTypes()
        self.writer = Writer(output, version=METADATA_VERSION, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.connections: dict[str, Connection] = {}
        self.skipped: set[str] = set()
        self.count = 0
        self.closed = False
        self.lock = threading.Lock()

    def selected(self, topic: str) -> bool:
        if self.wanted:
            return topic in self.wanted
        return self.include_hidden or not HIDDEN.search(topic)

    def discover(self) -> None:
        """Start recording each selected topic that has a publisher and no subscription yet."""
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self.connections or topic in self.skipped or not self.selected(topic):
                continue
            publishers = [p for p in self.node.get_publishers_info_by_topic(topic)
                          if p.topic_type == types[0]]
            if publishers:
                self.start(topic, types, publishers)

    def start(self, topic: str, types: list[str], publishers: list[TopicEndpointInfo]) -> None:
        type_name = types[0]
        if len(types) > 1:
            self.warn(f'{topic} has several types {types}: recording {type_name}')
        try:
            msg_class = message_class(type_name)
            self.types.ensure(type_name)
        except (ImportError, AttributeError, ValueError, LookupError, TypesysError) as exc:
            self.warn(f'not recording {topic}: type {type_name} unknown ({exc})')
            self.skipped.add(topic)
            return
        offers = [p.qos_profile for p in publishers]
        with self.lock:
            if self.closed:
                return
            self.connections[topic] = self.writer.add_connection(
                topic, type_name, typestore=self.types.store,
                offered_qos_profiles=[offered_qos(o) for o in offers])
        qos = subscription_qos(offers)
        self.node.create_subscription(
            msg_class, topic, lambda data, info, t=topic: self.write(t, data, info), qos,
            raw=True)
        reliability = 'reliable' if qos.reliability == ReliabilityPolicy.RELIABLE \
            else 'best effort'
        print(f'record_bag: recording {topic} [{type_name}] from {len(publishers)} '
              f'publisher(s), {reliability}', flush=True)

    def write(self, topic: str, data: bytes, info: dict[str, int]) -> None:
        # rosbag2 stamps each message with its receive time.
        stamp = info.get('received_timestamp') or time.time_ns()
        with self.lock:
            if self.closed:
                return
            self.writer.write(self.connections[topic], stamp, data)
            self.count += 1

    def warn(self, text: str) -> None:
        print(f'record_bag: {text}', file=sys.stderr, flush=True)

    def close(self) -> None:
        """Write the MCAP summary and metadata.yaml; messages arriving later are dropped."""
        with self.lock:
            if not self.closed:
                self.closed = True
                self.writer.close()


class Progress:
    """One progress line: redrawn in place on a terminal, a line every ``period`` s on a
    pipe or file (a log stays readable)."""

    def __init__(self, recorder: BagRecorder, period: float) -> None:
        self.recorder = recorder
        self.live = sys.stdout.isatty()
        self.period = 0.5 if self.live else period
        self.started = time.monotonic()
        self.next = self.started + self.period

    def line(self) -> str:
        return (f'record_bag: {time.monotonic() - self.started:.1f} s, '
                f'{self.recorder.count} messages on {len(self.recorder.connections)} topics')

    def update(self, final: bool = False) -> None:
        now = time.monotonic()
        if not final and now < self.next:
            return
        self.next = now + self.period
        if self.live:
            sys.stdout.write('\r\x1b[2K' + self.line() + ('\n' if final else ''))
            sys.stdout.flush()
        elif not final:
            print(self.line(), flush=True)


def positive(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f'must be > 0, got {text}')
    return value


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description='Record topics to a rosbag2 bag (MCAP storage), like '
                    '`ros2 bag record -s mcap`. Ctrl-C ends the recording cleanly.')
    parser.add_argument('topics', nargs='*', metavar='TOPIC',
                        help='topics to record (default: every topic, as with -a)')
    parser.add_argument('-a', '--all', action='store_true',
                        help='record every topic (hidden ones only with --include-hidden)')
    parser.add_argument('-o', '--output', type=Path,
                        help='bag directory to create (default: rosbag2_YYYY_MM_DD-HH_MM_SS)')
    parser.add_argument('-d', '--duration', type=positive, metavar='SECONDS',
                        help='stop by itself after this many seconds')
    parser.add_argument('--include-hidden', action='store_true',
                        help='with -a, also record hidden topics (/_action/ ...)')
    parser.add_argument('--progress-period', type=positive, default=5.0, metavar='SECONDS',
                        help='seconds between progress lines when not on a terminal')
    args = parser.parse_args(argv)
    if args.all and args.topics:
        parser.error('give either -a or TOPIC names, not both')
    bad = [t for t in args.topics if not t.startswith('/')]
    if bad:
        parser.error(f'topic names must be absolute (start with /): {" ".join(bad)}')
    if args.output is None:
        args.output = Path(time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S'))
    if args.output.exists():
        parser.error(f'{args.output} exists already; rosbag2 bags are never overwritten')
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    stop = threading.Event()
    # Before rclpy.init: an early Ctrl-C or SIGTERM still closes a valid bag.
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node('gimbal_bag_recorder')
    try:
        recorder = BagRecorder(node, args.output, args.topics, args.include_hidden)
    except (WriterError, OSError) as exc:
        print(f'record_bag: cannot create {args.output}: {exc}', file=sys.stderr)
        node.destroy_node()
        rclpy.try_shutdown()
        return 1
    print(f'record_bag: recording to {args.output} '
          f'({", ".join(args.topics) if args.topics else "every topic"}'
          f'{f", for {args.duration:g} s" if args.duration else ""}); Ctrl-C stops', flush=True)
    progress = Progress(recorder, args.progress_period)
    node.create_timer(0.5, recorder.discover)
    recorder.discover()
    end = time.monotonic() + args.duration if args.duration else None
    try:
        while not stop.is_set() and (end is None or time.monotonic() < end):
            rclpy.spin_once(node, timeout_sec=0.1)
            progress.update()
    finally:
        recorder.close()
        progress.update(final=True)
        missing = sorted(recorder.wanted - recorder.connections.keys())
        if missing:
            recorder.warn(f'no publisher seen on {", ".join(missing)}: not in the bag')
        print(f'record_bag: {recorder.count} messages on {len(recorder.connections)} topics '
              f'-> {args.output}', flush=True)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
