"""`scripts/record_bag.py` against a real run: the virtual gimbal simulator and its node.

Each bag is read back with two independent readers (``check_rosbag2`` in conftest.py); the
stored type hashes and offered QoS are compared with what the publishers advertise in the
ROS graph.
"""

from __future__ import annotations

import importlib.util
import json
import math
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
RECORDER = ROOT / 'scripts' / 'record_bag.py'
STATUS = '/virtual_gimbal_driver/status'
CHOSEN = {
    '/joint_states': 'sensor_msgs/msg/JointState',
    STATUS: 'gimbal_msgs/msg/GimbalStatus',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
}


@dataclass
class Gimbal:
    domain: int
    client: object  # RosTestClient


def load_script(name: str):
    """A script of scripts/ as a module, for the in-process tests."""
    spec = importlib.util.spec_from_file_location(Path(name).stem, ROOT / 'scripts' / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def load_recorder():
    return load_script('record_bag.py')


@pytest.fixture(scope='module')
def gimbal() -> Iterator[Gimbal]:
    """The reference simulator and node, publishing joint_states, status and diagnostics."""
    testing = pytest.importorskip('gimbal_driver_testing')
    ros_testing = pytest.importorskip('gimbal_driver_testing.ros')
    from sensor_msgs.msg import JointState

    with testing.DomainLease() as domain:
        port = testing.free_tcp_port()
        with testing.ManagedProcess.ros('virtual_gimbal_driver', 'virtual_gimbal_sim', domain,
                                        ['--port', str(port)]) as sim:
            sim.wait_for_output('{"ready": "virtual_gimbal_sim"', timeout=60)
            with testing.ManagedProcess.ros('virtual_gimbal_driver',
                                            'virtual_gimbal_driver_node', domain,
                                            ['--ros-args', '-p', f'port:={port}']) as node, \
                    ros_testing.RosTestClient(domain, 'record_bag_test') as client:
                try:
                    client.wait_for_message('/joint_states', JointState, timeout=90)
                    client.wait_for_message(STATUS, _status_type(), timeout=60)
                except TimeoutError:
                    pytest.fail(f'the virtual gimbal did not come up:\n{node.output()}')
                yield Gimbal(domain, client)


def _status_type() -> type:
    from gimbal_msgs.msg import GimbalStatus

    return GimbalStatus


def start_recorder(domain: int, *arguments: str):
    from gimbal_driver_testing import ManagedProcess, ros_env

    return ManagedProcess([sys.executable, str(RECORDER), *arguments], ros_env(domain),
                          name='record_bag')


def check_offers(gimbal: Gimbal, metadata: dict, topic: str) -> None:
    """The stored offered QoS and type hash are those of the topic's publishers."""
    publishers = gimbal.client.node.get_publishers_info_by_topic(topic)
    entry = next(e['topic_metadata'] for e in metadata['topics_with_message_count']
                 if e['topic_metadata']['name'] == topic)
    offered = entry['offered_qos_profiles']
    assert len(offered) == len(publishers) >= 1, (topic, offered)
    assert sorted(o['reliability'] for o in offered) == sorted(
        p.qos_profile.reliability.name.lower() for p in publishers)
    assert sorted(o['durability'] for o in offered) == sorted(
        p.qos_profile.durability.name.lower() for p in publishers)
    assert {entry['type_description_hash']} == {str(p.topic_type_hash) for p in publishers}


@pytest.mark.ros
def test_recorder_writes_chosen_topics_until_ctrl_c(gimbal, tmp_path, check_rosbag2):
    from sensor_msgs.msg import JointState

    bag = tmp_path / 'chosen'
    started = time.time_ns()
    recorder = start_recorder(gimbal.domain, '-o', str(bag), '--progress-period', '0.5',
                              *CHOSEN, '/nobody_publishes_this')
    try:
        for topic in CHOSEN:
            recorder.wait_for_output(f'recording {topic} [{CHOSEN[topic]}]', timeout=60)
        received = gimbal.client.subscribe('/joint_states', JointState)
        seen = len(received)
        testing = pytest.importorskip('gimbal_driver_testing')
        testing.wait_for(lambda: len(received) >= seen + 30, 60, '30 more joint_states')
        recorder.wait_for_output('messages on 3 topics', timeout=30)  # a progress line
    finally:
        code = recorder.stop(timeout=30)  # SIGINT, as Ctrl-C
    ended = time.time_ns()
    out = recorder.output()
    assert code == 0, out
    assert re.search(r'^record_bag: \d+\.\d s, \d+ messages on 3 topics$', out, re.MULTILINE)
    final = re.search(rf'^record_bag: (\d+) messages on 3 topics -> {re.escape(str(bag))}$',
                      out, re.MULTILINE)
    assert final, out
    assert 'no publisher seen on /nobody_publishes_this: not in the bag' in out

    metadata, types, messages = check_rosbag2(bag, started, ended)
    assert types == CHOSEN
    assert metadata['message_count'] == int(final.group(1))
    joint_states = [m for topic, _, m in messages if topic == '/joint_states']
    assert len(joint_states) >= 10
    assert all(list(m.name) == ['pan', 'tilt'] for m in joint_states)
    assert all(m.header.stamp.sec > 0 for m in joint_states)
    statuses = [m for topic, _, m in messages if topic == STATUS]
    assert statuses and all([a.name for a in m.axes] == ['pan', 'tilt'] for m in statuses)
    for topic in CHOSEN:
        check_offers(gimbal, metadata, topic)

    # The plot tool reads the same bag: actual from /joint_states, commanded from status.
    plot_bag = load_script('plot_bag.py')
    actual, _ = plot_bag.read_series(bag)
    assert set(actual['/']) == {'pan', 'tilt'}
    assert len(actual['/']['pan']) == len(joint_states)
    png = plot_bag.plot(bag, tmp_path / 'positions.png')
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    # the virtual gimbal reports no motor current: no effort, no current or effort rows
    assert all(len(m.effort) == 0 for m in joint_states)
    assert all(math.isnan(a.current) for m in statuses for a in m.axes)
    assert plot_bag.rows_of(plot_bag.read_bag(bag)) == [('/', '')]


@pytest.mark.ros
def test_recorder_all_topics_for_a_duration(gimbal, tmp_path, check_rosbag2):
    from sensor_msgs.msg import JointState

    bag = tmp_path / 'all'
    started = time.time_ns()
    recorder = start_recorder(gimbal.domain, '-a', '-d', '6', '-o', str(bag))
    try:
        recorder.wait_for_output('recording /joint_states', timeout=60)
        # A topic that appears while recording is picked up once it has a publisher.
        command = JointState(name=['pan'], position=[0.05])
        gimbal.client.publish('/joint_command', command)
        recorder.wait_for_output('recording /joint_command', timeout=30)
        for _ in range(5):
            gimbal.client.publish('/joint_command', command)
            time.sleep(0.1)
        recorder.process.wait(timeout=90)  # -d ends it by itself
    finally:
        recorder.stop()
    ended = time.time_ns()
    out = recorder.output()
    assert recorder.process.returncode == 0, out

    metadata, types, messages = check_rosbag2(bag, started, ended)
    for topic, type_name in CHOSEN.items():
        assert types[topic] == type_name
    assert types['/joint_command'] == 'sensor_msgs/msg/JointState'
    assert types['/rosout'] == 'rcl_interfaces/msg/Log'
    assert types['/parameter_events'] == 'rcl_interfaces/msg/ParameterEvent'
    assert not [t for t in types if '/_' in t], 'hidden topics recorded without asking'
    commands = [m for topic, _, m in messages if topic == '/joint_command']
    assert commands and all(list(m.position) == [0.05] for m in commands)
    check_offers(gimbal, metadata, '/joint_command')
    check_offers(gimbal, metadata, STATUS)


@pytest.mark.parametrize(('arguments', 'complaint'), [
    (['joint_states'], 'topic names must be absolute'),
    (['-d', '0', '/joint_states'], 'must be > 0'),
    (['-a', '/joint_states'], 'either -a or TOPIC'),
])
def test_recorder_refuses_bad_arguments(tmp_path, arguments, complaint):
    bag = tmp_path / 'bag'
    done = subprocess.run([sys.executable, str(RECORDER), '-o', str(bag), *arguments],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert complaint in done.stderr
    assert 'Traceback' not in done.stderr
    assert not bag.exists()


def test_recorder_never_overwrites_a_bag(tmp_path):
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('kept\n')
    done = subprocess.run([sys.executable, str(RECORDER), '-o', str(bag), '/joint_states'],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert 'exists already' in done.stderr and 'Traceback' not in done.stderr
    assert (bag / 'metadata.yaml').read_text() == 'kept\n'


def test_workspace_types_registers_msg_files_with_their_dependencies(tmp_path):
    """A type rosbags does not ship is registered from its package's .msg files, and so are
    the packages it refers to; its definition and hash come out as for a shipped type."""
    recorder = load_recorder()
    (tmp_path / 'share' / 'rig_msgs' / 'msg').mkdir(parents=True)
    (tmp_path / 'share' / 'rig_msgs' / 'msg' / 'Rig.msg').write_text(
        'std_msgs/Header header\nlens_msgs/Lens[] lenses\nRigMode mode\n')
    (tmp_path / 'share' / 'rig_msgs' / 'msg' / 'RigMode.msg').write_text(
        'uint8 IDLE=0\nuint8 value\n')
    (tmp_path / 'share' / 'lens_msgs' / 'msg').mkdir(parents=True)
    (tmp_path / 'share' / 'lens_msgs' / 'msg' / 'Lens.msg').write_text('float64 zoom\n')
    types = recorder.WorkspaceTypes([str(tmp_path)])
    types.ensure('rig_msgs/msg/Rig')
    for name in ('rig_msgs/msg/Rig', 'rig_msgs/msg/RigMode', 'lens_msgs/msg/Lens'):
        assert name in types.store.fielddefs
    definition, _ = types.store.generate_msgdef('rig_msgs/msg/Rig', ros_version=2)
    assert 'lens_msgs/msg/Lens[] lenses' in definition or 'lens_msgs/Lens[] lenses' in definition
    assert types.store.hash_rihs01('rig_msgs/msg/Rig').startswith('RIHS01_')
    with pytest.raises(LookupError, match='no share/absent_msgs/msg'):
        types.ensure('absent_msgs/msg/Thing')
    with pytest.raises(LookupError, match=r'not among the \.msg files of rig_msgs'):
        types.ensure('rig_msgs/msg/Missing')


def test_workspace_types_hash_as_rosidl_generated_them():
    """Every gimbal_msgs message registered from its installed .msg file hashes exactly as
    rosidl hashed it at build time (share/gimbal_msgs/msg/*.json), so the definitions and
    hashes in a bag are the ones the nodes advertise."""
    recorder = load_recorder()
    types = recorder.WorkspaceTypes()
    files = types.msg_files('gimbal_msgs')
    if not files:
        pytest.skip('gimbal_msgs is not built (make build)')
    for path in files:
        name = f'gimbal_msgs/msg/{path.stem}'
        generated = json.loads(path.with_suffix('.json').read_text())['type_hashes']
        types.ensure(name)
        expected = {h['type_name']: h['hash_string'] for h in generated}
        assert types.store.hash_rihs01(name) == expected[name], name


def test_subscription_adapts_to_the_offers():
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    recorder = load_recorder()
    reliable_latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                  durability=DurabilityPolicy.TRANSIENT_LOCAL)
    best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
    both = recorder.subscription_qos([reliable_latched, best_effort])
    assert both.reliability == ReliabilityPolicy.BEST_EFFORT
    assert both.durability == DurabilityPolicy.VOLATILE
    only = recorder.subscription_qos([reliable_latched])
    assert only.reliability == ReliabilityPolicy.RELIABLE
    assert only.durability == DurabilityPolicy.TRANSIENT_LOCAL
    stored = recorder.offered_qos(reliable_latched)
    assert (stored.reliability.name, stored.durability.name, stored.depth) == (
        'RELIABLE', 'TRANSIENT_LOCAL', 1)


def test_the_commanded_line_shows_what_each_step_commanded() -> None:
    """The demo plot's dashed line: a move target is held until the next command; a jog, a
    scan, a homing or a playback takes over (a gap: the old target is no longer what was
    commanded), a playback's key frames are dots at their times, and the line resumes
    where the playback ends."""
    plot_bag = load_script('plot_bag.py')
    records = [
        {'ns': '/g', 'kind': 'target', 't': 100.0, 'positions': {'pan': 0.4, 'tilt': -0.2}},
        {'ns': '/g', 'kind': 'jog', 't': 102.0, 'joint': 'pan', 'velocity': 0.3,
         't0': 102.0, 't1': 103.5},
        {'ns': '/g', 'kind': 'target', 't': 105.0, 'positions': {'pan': 0.4, 'tilt': -0.2}},
        {'ns': '/g', 'kind': 'scan', 't': 107.0, 't0': 107.0, 't1': 111.0,
         'corners': {'pan': [-0.2, 0.2]}},
        {'ns': '/g', 'kind': 'home', 't': 112.0},
        {'ns': '/g', 'kind': 'keyframes', 't': 120.0, 'joint_names': ['pan', 'tilt'],
         'points': [[0.0, [-0.5, -0.2]], [3.0, [1.2, 0.4]]]},
    ]
    xs, ys, dots = plot_bag.commanded_lines(records, 'pan', 100.0)
    assert xs == [0.0, 2.0, 5.0, 7.0, 12.0, 20.0, 23.0]
    assert ys[:3] == [0.4, pytest.approx(float('nan'), nan_ok=True), 0.4]
    assert [y != y for y in ys] == [False, True, False, True, True, True, False]
    assert ys[-1] == 1.2 and dots == [(20.0, -0.5), (23.0, 1.2)]
    # tilt was not jogged or scanned: its target holds through them, until the homing
    xs, ys, _ = plot_bag.commanded_lines(records, 'tilt', 100.0)
    assert xs[:3] == [0.0, 5.0, 12.0] and ys[:2] == [-0.2, -0.2] and ys[2] != ys[2]


def test_the_plot_names_the_steps_and_says_what_the_line_means(tmp_path: Path) -> None:
    """With the demo's command file the figure's caption explains the dashed line."""
    plot_bag = load_script('plot_bag.py')
    assert 'Dashed: what the demo commanded' in plot_bag.CAPTION
    commands = tmp_path / 'demo_commands.json'
    commands.write_text(json.dumps([
        {'ns': '/g', 'kind': 'step', 't': 101.0, 'name': 'move', 't0': 100.0, 't1': 101.0}]))
    assert plot_bag.load_commands(commands)['/g'][0]['name'] == 'move'
    assert plot_bag.load_commands(tmp_path / 'missing.json') == {}


def test_the_plot_shows_current_in_amperes_and_effort_as_torque(tmp_path: Path) -> None:
    """A bag with ~/status currents and joint_states efforts (a node with torque_constants)
    gets a current row in A and an effort row in N·m, each saying where it came from."""
    pytest.importorskip('gimbal_msgs')
    from rclpy.serialization import serialize_message
    from rosbags.rosbag2 import StoragePlugin, Writer
    from sensor_msgs.msg import JointState

    from gimbal_msgs.msg import AxisState, GimbalStatus

    recorder, plot_bag = load_recorder(), load_script('plot_bag.py')
    types = recorder.WorkspaceTypes()
    if not types.msg_files('gimbal_msgs'):
        pytest.skip('gimbal_msgs is not built (make build)')
    types.ensure('gimbal_msgs/msg/GimbalStatus')
    bag = tmp_path / 'torque'
    writer = Writer(bag, version=recorder.METADATA_VERSION, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    states = writer.add_connection('/turret/joint_states', 'sensor_msgs/msg/JointState',
                                   typestore=types.store)
    status = writer.add_connection('/turret/canaero_turret_driver/status',
                                   'gimbal_msgs/msg/GimbalStatus', typestore=types.store)
    for step in range(3):
        t = 1_000_000_000 * (step + 1)
        writer.write(states, t, serialize_message(JointState(
            name=['yaw', 'pitch'], position=[0.1 * step, 0.0], velocity=[0.0, 0.0],
            effort=[0.5 * step, float('nan')])))
        writer.write(status, t, serialize_message(GimbalStatus(axes=[
            AxisState(name='yaw', current=1.0 * step, target_position=float('nan')),
            AxisState(name='pitch', current=2.0, target_position=float('nan'))])))
    writer.close()
    series = plot_bag.read_bag(bag)
    assert series.current['/turret'] == {'yaw': [(1.0, 0.0), (2.0, 1.0), (3.0, 2.0)],
                                         'pitch': [(1.0, 2.0), (2.0, 2.0), (3.0, 2.0)]}
    assert series.effort['/turret'] == {'yaw': [(1.0, 0.0), (2.0, 0.5), (3.0, 1.0)]}
    assert plot_bag.rows_of(series) == [('/turret', ''), ('/turret', 'current'),
                                        ('/turret', 'effort')]
    fig = plot_bag.figure(series, {})
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == ['position [rad or m]', 'motor current [A]',
                      'effort (torque) [N·m; N linear]']
    assert 'AxisState.current' in fig.axes[1].get_title()
    assert 'torque_constants' in fig.axes[2].get_title()
    png = plot_bag.plot(bag, tmp_path / 'torque.png')
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
