"""Shared checks of the rosbag2 bags the demo and scripts/record_bag.py write.

A bag is read back with two readers that share nothing with the writer's type store:
``rosbags``' AnyReader (builds its types from the definitions stored in the bag and checks
them against the stored RIHS01 hashes) and the ``mcap`` library with ``mcap_ros2``'s
decoder (decodes by the MCAP schemas).
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

Messages = list[tuple[str, int, object]]


def read_metadata(bag: Path) -> dict:
    return yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def read_with_rosbags(bag: Path) -> tuple[dict[str, str], Messages]:
    """(topic -> stored type name, [(topic, timestamp, message)]) with rosbags' reader."""
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        messages = [(c.topic, stamp, reader.deserialize(raw, c.msgtype))
                    for c, stamp, raw in reader.messages()]
    return types, messages


def read_with_mcap(bag: Path, metadata: dict) -> Counter:
    """Per-topic counts, decoding every message by the MCAP schema stored with it."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    [relative] = metadata['relative_file_paths']
    counts: Counter = Counter()
    with (bag / relative).open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, _, decoded in reader.iter_decoded_messages():
            assert schema.encoding == 'ros2msg'
            assert schema.name == metadata_type(metadata, channel.topic)
            assert 'offered_qos_profiles' in channel.metadata
            assert decoded is not None
            counts[channel.topic] += 1
        # The MCAP file alone also describes the bag (what rosbag2 reads without metadata.yaml).
        records = {r.name: r.metadata for r in reader.iter_metadata()}
    stored = yaml.safe_load(records['rosbag2']['serialized_metadata'])
    assert stored['version'] == metadata['version']
    assert stored['topics_with_message_count'] == metadata['topics_with_message_count']
    return counts


def metadata_type(metadata: dict, topic: str) -> str:
    for entry in metadata['topics_with_message_count']:
        if entry['topic_metadata']['name'] == topic:
            return entry['topic_metadata']['type']
    raise KeyError(topic)


def check_bag(bag: Path, started_ns: int, ended_ns: int) -> tuple[dict, dict[str, str], Messages]:
    """What holds for every bag: rosbag2 layout and metadata, counts and timestamps agree
    between metadata.yaml and both readers. Returns (metadata, types, messages)."""
    metadata = read_metadata(bag)
    assert metadata['version'] == 9  # what ROS 2 Jazzy's rosbag2 writes
    assert metadata['storage_identifier'] == 'mcap'
    [relative] = metadata['relative_file_paths']
    assert (bag / relative).is_file() and relative.endswith('.mcap')

    types, messages = read_with_rosbags(bag)
    counts = Counter(topic for topic, _, _ in messages)
    listed = {e['topic_metadata']['name']: e for e in metadata['topics_with_message_count']}
    assert set(listed) == set(types)
    for topic, entry in listed.items():
        assert re.fullmatch(r'[a-z0-9_]+/msg/[A-Za-z0-9]+', entry['topic_metadata']['type'])
        assert entry['topic_metadata']['type'] == types[topic]
        assert entry['topic_metadata']['serialization_format'] == 'cdr'
        assert entry['message_count'] == counts[topic], topic
    assert metadata['message_count'] == len(messages)
    assert read_with_mcap(bag, metadata) == counts

    stamps = [stamp for _, stamp, _ in messages]
    assert stamps == sorted(stamps)
    assert started_ns <= stamps[0] and stamps[-1] <= ended_ns
    assert metadata['starting_time']['nanoseconds_since_epoch'] == stamps[0]
    assert metadata['duration']['nanoseconds'] == stamps[-1] - stamps[0]
    return metadata, types, messages


@pytest.fixture
def check_rosbag2() -> Callable[[Path, int, int], tuple[dict, dict[str, str], Messages]]:
    """``check(bag, started_ns, ended_ns) -> (metadata, topic types, messages)``."""
    pytest.importorskip('rosbags')
    pytest.importorskip('mcap_ros2')
    return check_bag
