"""A test never commands a system it did not start.

Discovery on localhost does not separate the processes of one host: a test that leased the
domain a robot's nodes run on would publish ``/joint_command`` to them. Before the ROS test
client first publishes on a topic, calls a service or sends an action goal, it reads the ROS
graph and refuses (:class:`ForeignNodesError`) while a node of a process outside the test
run is on the domain.

Which process a node belongs to is read from the GUID of its endpoints (every rclpy and
rclcpp node publishes ``/rosout`` and ``/parameter_events``), never from its name (two
processes can both run a ``/gimbal_test_client``): Fast DDS, the RMW of ROS 2 Jazzy, writes
the vendor id ``01.0f`` in bytes 0-1 of the GUID prefix and the low 16 bits of the process
id (little-endian) in bytes 4-5. A node is the test run's when that process is the run's
root (:func:`run_root`: the pytest-xdist controller, or the pytest process itself), one
this process started (:data:`gimbal_driver_testing.STARTED_PIDS`) or a descendant of
either: the parallel workers and what they started are the run's own, since a participant
of a sibling worker's earlier lease may still be seen for a moment after its lease ended;
a process outside that tree, e.g. a robot's nodes, is foreign. An endpoint whose process
no longer exists is the discovery trace of a stopped node (removed after its lease) and
counts as no one's. An endpoint of another DDS vendor cannot be told apart and counts as
foreign. Only 16 bits of the pid are there: where ``pid_max`` is above 65536, an unrelated
live process can share them with a stopped node's (then the refusal names that node), or
with a foreign node's (then it is missed), so the domain pool is the first guard and this
one the second.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from gimbal_driver_testing import DOMAINS_VARIABLE, STARTED_PIDS

#: eProsima's DDS vendor id, the first two bytes of a Fast DDS GUID prefix
FAST_DDS_VENDOR = b'\x01\x0f'


class ForeignNodesError(RuntimeError):
    """Nodes of processes outside the test run are on its domain."""


def participant_pid_bits(gid: Iterable[int]) -> int | None:
    """The low 16 bits of the process id in a Fast DDS endpoint GID, None for another
    vendor's."""
    raw = bytes(gid)
    if raw[:2] != FAST_DDS_VENDOR or len(raw) < 6:
        return None
    return int.from_bytes(raw[4:6], 'little')


def live_processes(proc: Path = Path('/proc')) -> dict[int, int]:
    """pid -> parent pid of every process now running (Linux ``/proc/<pid>/stat``)."""
    parents: dict[int, int] = {}
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / 'stat').read_text(encoding='utf-8', errors='replace')
        except OSError:
            continue   # ended while we read
        # pid (comm) state ppid ...: comm may hold spaces and parentheses, so split after ')'
        parents[int(entry.name)] = int(stat.rpartition(')')[2].split()[1])
    return parents


def run_root(environ: Mapping[str, str] = os.environ) -> int:
    """The root process of this test run: the pytest-xdist controller when this is one of
    its workers (``PYTEST_XDIST_WORKER``; execnet starts each worker as its child), else
    this process. Nothing above it counts: the shell or ``make`` that started the run may
    also have started a live system."""
    return os.getppid() if environ.get('PYTEST_XDIST_WORKER') else os.getpid()


def own_pids(parents: Mapping[int, int], me: int, started: Iterable[int]) -> set[int]:
    """``me``, the processes it started and every live descendant of either."""
    own = {me, *started}
    grew = True
    while grew:
        grew = False
        for pid, parent in parents.items():
            if parent in own and pid not in own:
                own.add(pid)
                grew = True
    return own


def foreign_nodes(endpoints: Iterable[tuple[str, Iterable[int]]],
                  parents: Mapping[int, int], own: set[int]) -> list[str]:
    """The nodes among ``(node, gid)`` endpoints whose live process is not ``own``, each
    with that process (the low 16 bits of its pid)."""
    own_bits = {pid & 0xFFFF for pid in own}
    live_bits = {pid & 0xFFFF for pid in parents}
    foreign: set[str] = set()
    for node, gid in endpoints:
        bits = participant_pid_bits(gid)
        if bits is None:
            foreign.add(f'{node} (not a Fast DDS participant: its process cannot be told)')
        elif bits in live_bits and bits not in own_bits:
            foreign.add(f'{node} (pid {bits})')
    return sorted(foreign)


def graph_endpoints(node: Any) -> list[tuple[str, list[int]]]:
    """(full node name, endpoint gid) of every publisher and subscription ``node`` sees."""
    found = []
    for topic, _types in node.get_topic_names_and_types():
        for info in (*node.get_publishers_info_by_topic(topic),
                     *node.get_subscriptions_info_by_topic(topic)):
            name = f'{info.node_namespace.rstrip("/")}/{info.node_name}'
            found.append((name, list(info.endpoint_gid)))
    return found


def refuse_foreign_nodes(node: Any, domain_id: int, what: str) -> None:
    """Raise :class:`ForeignNodesError` before ``what`` while ``node`` sees a node of a
    process outside this test run."""
    parents = live_processes()
    foreign = foreign_nodes(graph_endpoints(node), parents,
                            own_pids(parents, run_root(), STARTED_PIDS))
    if foreign:
        raise ForeignNodesError(
            f'refusing to {what} in ROS domain {domain_id}: nodes of processes outside '
            f'this test run are on it ({", ".join(foreign)}); a live system may use this '
            f'domain. Give the tests other domains with {DOMAINS_VARIABLE} (docs/testing.md, '
            '"Beside a live system")')
