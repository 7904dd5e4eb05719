"""ARCHITECTURE.md's thread list is what a running node of each driver has.

Each registered driver's node runs against its simulator (the registry's in-process
``SimHandle``) under ``tests/node_thread_probe.py``, which reports the names of the node
process's threads. Every thread it has must be a row of the list for that driver, and
every row the list says is there ``always`` must be among them.
"""

from __future__ import annotations

import json
import re
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_common.registry import DriverSpec, drivers
from gimbal_driver_common.sim_handle import make_handle
from gimbal_driver_testing import DomainLease, ManagedProcess, ros_env, wait_for
from gimbal_driver_testing.ros import RosTestClient
from gimbal_msgs.srv import StartScan

ROOT = Path(__file__).resolve().parent.parent
PROBE = Path(__file__).resolve().parent / 'node_thread_probe.py'
LIST_START, LIST_END = '<!-- thread list -->', '<!-- /thread list -->'


@dataclass(frozen=True)
class ThreadRow:
    """One row of ARCHITECTURE.md's thread list."""

    pattern: re.Pattern[str]  # the name; ``<n>`` stands for a number
    drivers: frozenset[str]   # registry names, or empty for every driver
    always: bool              # there from activation to shutdown (else: while something runs)

    def applies_to(self, driver: str) -> bool:
        return not self.drivers or driver in self.drivers


def thread_list() -> list[ThreadRow]:
    """The rows between the thread-list markers: | `name` | drivers | when | what |."""
    text = (ROOT / 'ARCHITECTURE.md').read_text(encoding='utf-8')
    table = text[text.index(LIST_START) + len(LIST_START):text.index(LIST_END)]
    rows = []
    for line in table.splitlines():
        cells = [cell.strip() for cell in line.strip().strip('|').split('|')]
        if len(cells) < 3 or not cells[0].startswith('`'):
            continue
        name = cells[0].strip('`')
        pattern = re.compile(re.escape(name).replace(re.escape('<n>'), r'\d+') + '$')
        named = re.findall(r'`(\w+)`', cells[1])
        rows.append(ThreadRow(pattern, frozenset(named), cells[2].startswith('always')))
    return rows


def test_the_thread_list_parses_and_names_registered_drivers() -> None:
    rows = thread_list()
    assert len(rows) >= 10
    registered = {spec.name for spec in drivers()}
    assert all(row.drivers <= registered for row in rows), 'a row names an unknown driver'
    assert any(row.pattern.match('executor-pool_3') for row in rows)


def reported_threads(node: ManagedProcess, out: Path) -> set[str]:
    """The node's thread names now (one SIGUSR1 to the probe, then its answer)."""
    out.unlink(missing_ok=True)
    node.process.send_signal(signal.SIGUSR1)
    wait_for(lambda: out.exists() or not node.running, 10, 'the thread report')
    assert node.running, node.output()
    return set(json.loads(out.read_text()))


@pytest.mark.ros
@pytest.mark.parametrize('spec', [spec for spec in drivers() if spec.sim_handle],
                         ids=lambda spec: spec.name)
def test_a_running_node_has_the_threads_the_architecture_lists(spec: DriverSpec,
                                                                tmp_path: Path) -> None:
    rows = [row for row in thread_list() if row.applies_to(spec.name)]
    device = make_handle(spec, tmp_path, process_tests=True)
    device.start()
    out = tmp_path / 'threads.json'
    try:
        with DomainLease() as domain:
            arguments = ['--ros-args', *[x for p in [*device.link_parameters(),
                                                     f'presets_file:={tmp_path / "p.yaml"}']
                                         for x in ('-p', p)]]
            node = ManagedProcess([sys.executable, str(PROBE), str(out), spec.node_executable,
                                   *arguments], ros_env(domain), name=spec.node_executable)
            ros = RosTestClient(domain, 'thread_list_client')
            try:
                node.wait_for_output('active: publishing joint_states', 60)
                # service calls run in the executor's pool, and the demo's scan may start
                # the driver-side scan thread: their threads must be listed too
                # (both requests may run twice: a second start restarts the same scan)
                if spec.demo.scan is not None:
                    # a scan starts from the current position: "active" comes before the
                    # first sample on a loaded core ("no current position yet")
                    ros.wait_for_message('/joint_states', JointState, timeout=60)
                    reply = ros.call(StartScan, f'/{spec.node_name}/start_scan',
                                     StartScan.Request(**spec.demo.scan), timeout=30,
                                     idempotent=True)
                    assert reply.success, reply.message
                always = [row for row in rows if row.always]
                seen: set[str] = set()
                deadline = time.monotonic() + 30  # threads of the link may still be starting
                while True:
                    now = reported_threads(node, out)
                    seen |= now
                    missing = [row.pattern.pattern for row in always
                               if not any(row.pattern.match(name) for name in now)]
                    if not missing or time.monotonic() > deadline:
                        break
                    time.sleep(0.2)
                assert missing == [], f'listed as always there but not running: {missing}'
                reply = ros.call(Trigger, f'/{spec.node_name}/stop', Trigger.Request(),
                                 timeout=30, idempotent=True)
                assert reply.success, reply.message
                seen |= reported_threads(node, out)
                assert any(name.startswith('executor-pool_') for name in seen)
                unlisted = sorted(name for name in seen
                                  if not any(row.pattern.match(name) for row in rows))
                assert unlisted == [], f'threads ARCHITECTURE.md does not list for {spec.name}'
            finally:
                ros.close()
                node.stop()
    finally:
        device.stop()
