"""`scripts/demo.py` end to end: every simulator and driver, the rosbag2 bag, the plot.

Runs the demo as a user would (``source scripts/ros_env.sh; python scripts/demo.py``) into a
temporary output directory, then checks that it exited 0 with every driver OK, that the bag
is a rosbag2 bag whose every message both independent readers decode under its stored type
name (``check_rosbag2``), holding each driver's joint_states with its joint names and its
status, with no device password in it, that the plot is a PNG, and that no simulator or node
outlived it.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import time
from collections import defaultdict
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parent.parent


EXECUTABLES = ('_sim', '_node', 'record_bag.py')


def processes_in_domain(domain: str) -> list[str]:
    """Command lines of this user's demo processes (simulators, nodes, recorder) that run
    in ROS domain ``domain``."""
    found = []
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            environ = (entry / 'environ').read_bytes().split(b'\0')
            cmdline = (entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode()
        except OSError:
            continue
        if f'ROS_DOMAIN_ID={domain}'.encode() in environ and any(
                name in cmdline for name in EXECUTABLES) and str(ROOT) in cmdline:
            found.append(f'{entry.name}: {cmdline}')
    return found


def node_warnings(output: Path) -> str:
    """The failed steps and each log's warnings and errors, for the failure message: the
    demo's directory is pytest's, and a later run may have removed it by the time one reads
    the report."""
    parts = []
    failures = output / 'demo_failures.log'
    if failures.exists():
        parts.append(f'--- {failures.name}\n{failures.read_text()[-4000:]}')
    for log in sorted(output.glob('*.log')):
        if log == failures:
            continue
        lines = [line for line in log.read_text(errors='replace').splitlines()
                 if '[WARN]' in line or '[ERROR]' in line]
        if lines:
            parts.append(f'--- {log.name} (warnings and errors)\n' + '\n'.join(lines[-40:]))
    return '\n' + '\n'.join(parts)


#: an outer deadline for the whole demo (it ends as soon as it is done: about 2 min, pinned
#: to one core): its steps' own deadlines are up to 60 s (docs/testing.md)
DEMO_DEADLINE_S = 420


@pytest.mark.timeout(DEMO_DEADLINE_S + 120)
def test_demo_drives_every_driver_and_records_a_bag(tmp_path, check_rosbag2):
    if not (ROOT / 'install' / 'setup.bash').exists():
        pytest.skip('the workspace is not built (make build)')
    from gimbal_driver_common.registry import drivers

    specs = drivers()
    # namespace -> (node name, joint names): the demo runs every registered driver
    expected = {spec.namespace: (spec.node_name, set(spec.joints)) for spec in specs}
    assert len(expected) >= 5, f'fewer drivers registered than the suite has: {expected}'
    output = tmp_path / 'demo'
    command = f'source scripts/ros_env.sh && exec python scripts/demo.py --output {output}'
    env = {k: v for k, v in os.environ.items() if k != 'ROS_DOMAIN_ID'}
    started = time.time_ns()
    demo = subprocess.Popen(['bash', '-c', command], cwd=ROOT, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        out, _ = demo.communicate(timeout=DEMO_DEADLINE_S)
    except subprocess.TimeoutExpired:
        demo.send_signal(signal.SIGINT)  # the demo stops its processes on Ctrl-C
        out, _ = demo.communicate(timeout=60)
        pytest.fail(f'the demo did not finish within {DEMO_DEADLINE_S} s:\n{out[-6000:]}')
    ended = time.time_ns()
    assert demo.returncode == 0, out[-6000:] + node_warnings(output)
    for node, _ in expected.values():
        assert re.search(rf'\[{node}\]: OK$', out, re.MULTILINE), f'{node} not OK:\n{out}'
    assert 'failed' not in out.split('demo summary', 1)[1]

    domain = re.search(r'ROS_DOMAIN_ID=(\d+)', out).group(1)
    assert processes_in_domain(domain) == [], 'processes left after the demo'

    bag = output / 'demo_bag'
    assert re.search(rf'bag: {re.escape(str(bag))} \(rosbag2, MCAP storage; \d+ messages', out)
    _, types, messages = check_rosbag2(bag, started, ended)
    joints: dict[str, set[str]] = defaultdict(set)
    counts: dict[str, int] = defaultdict(int)
    for topic, _, msg in messages:
        if topic.endswith('/joint_states'):
            namespace = topic.rsplit('/', 1)[0]
            joints[namespace].update(msg.name)
            counts[namespace] += 1
    for namespace, (node, names) in expected.items():
        assert types[f'{namespace}/joint_states'] == 'sensor_msgs/msg/JointState'
        assert types[f'{namespace}/{node}/status'] == 'gimbal_msgs/msg/GimbalStatus'
        assert counts[namespace] > 20, f'{namespace}/joint_states: {counts[namespace]} messages'
        assert joints[namespace] == names, namespace
    assert types['/diagnostics'] == 'diagnostic_msgs/msg/DiagnosticArray'
    passwords = [spec.password for spec in specs if spec.password]
    assert passwords, 'no registered driver has a device password (Kessler has)'
    for path in bag.iterdir():
        for password in passwords:
            assert password.encode() not in path.read_bytes(), f'a device password is in {path}'

    plot = output / 'positions.png'
    assert plot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    # what the plot's dashed line is drawn from: each step of each driver, named and timed,
    # with what it commanded
    commands = json.loads((output / 'demo_commands.json').read_text())
    for spec in specs:
        mine = [c for c in commands if c['ns'] == spec.namespace]
        steps = [c['name'] for c in mine if c['kind'] == 'step']
        assert steps[:3] == ['move', 'jog', 'preset'], (spec.namespace, steps)
        assert all(started / 1e9 <= c['t'] <= ended / 1e9 for c in mine)
        kinds = {c['kind'] for c in mine}
        assert {'target', 'jog'} <= kinds, (spec.namespace, kinds)
        if spec.demo.scan is not None:
            assert 'scan' in kinds, spec.namespace
        if any(label == 'home' for label, _ in spec.demo.extra_steps):
            assert 'home' in kinds, spec.namespace
    assert any(c['kind'] == 'keyframes' for c in commands), 'no playback key frames'
    for node, _ in expected.values():
        assert (output / f'{node}.log').is_file()
