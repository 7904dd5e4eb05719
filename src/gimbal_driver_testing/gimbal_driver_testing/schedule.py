"""pytest plugin: under pytest-xdist, the tests that mostly wait for long go out first.

xdist's default ``load`` scheduling hands the collection out in its order, in chunks of
consecutive tests. The suite's longest tests (a soak per driver, 40 s each; the generated
driver's build and conformance suite, about 2 minutes; the demo, 35 s) are collected last
(``tests/``), so they started in a run's last minute, and the run ended with two or three
workers waiting on them while the others had finished (docs/testing.md, "Where the time
goes"). The node-id prefixes in the ``long_tests`` ini option name those tests. They go out
first, in the order listed, each to a worker of its own, on at most 3 in 8 of the workers
at a time (``LONG_SHARE``: the rest keep the CPU-bound tests going beside them; with half
of the workers on them, the two cores stood 40 % idle for the run's first 100 s, since the
long tests mostly wait). Every other test goes out as ``load`` hands it out: consecutive
chunks, refilled when a worker runs low, so a class's or a module's tests mostly stay on
one worker and its rig starts once there; but the classes and modules go out costliest
first, by the worker seconds each took in a recorded run (the ``test_durations`` ini option
names the file; ``pytest --record-test-durations`` writes it), so the run ends on cheap
tests in small chunks, not on a driver's conformance class handed out late (one ran 80 s
past the others). A class or module the file does not know goes after those it does, in
collection order.

The scheduler keeps to xdist's scheduling protocol (``xdist.scheduler.protocol.Scheduling``,
the contract of its ``pytest_xdist_make_scheduler`` hook), so this module imports nothing of
xdist, and without xdist, or with another ``--dist``, the hook returns nothing and xdist's
own scheduler runs.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import pytest

LONG_TESTS_INI = 'long_tests'
DURATIONS_INI = 'test_durations'
RECORD_OPTION = '--record-test-durations'
#: the share of the workers (rounded up) that may run long tests at once while others are left
LONG_SHARE = 3 / 8


class Worker(Protocol):
    """What the scheduler uses of xdist's ``WorkerController``."""

    shutting_down: bool

    def send_runtest_some(self, indices: Sequence[int]) -> None: ...

    def shutdown(self) -> None: ...


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addini(LONG_TESTS_INI, 'node-id prefixes of tests that mostly wait for long: under '
                  'pytest-xdist they go out first, each to a worker of its own '
                  '(gimbal_driver_testing.schedule)', type='linelist', default=[])
    parser.addini(DURATIONS_INI, 'file (from the rootdir) of the worker seconds each test '
                  'class or module took: under pytest-xdist the costliest go out first',
                  default='')
    parser.addoption(RECORD_OPTION, action='store_true',
                     help=f'write the worker seconds of each test class or module to the '
                     f'{DURATIONS_INI} file (under pytest-xdist)')


def worker_count(tx_specs: Sequence[str]) -> int:
    """How many workers xdist starts for its ``--tx`` specs (``-n 8`` is ``8*popen``), as
    xdist's own ``parse_tx_spec_config`` counts them."""
    count = 0
    for spec in tx_specs:
        times, star, _ = spec.partition('*')
        count += int(times) if star and times.isdigit() else 1
    return count


def rig_of(nodeid: str) -> str:
    """The class, or else the module, of a test: what its shared rig is scoped to."""
    parts = nodeid.split('::')
    return '::'.join(parts[:2]) if len(parts) > 2 else parts[0]


def durations_path(config: pytest.Config) -> Path | None:
    name = config.getini(DURATIONS_INI)
    return config.rootpath / name if name else None


def read_durations(path: Path | None) -> dict[str, float]:
    """The recorded seconds per class or module; none if the file is missing or unreadable
    (the order is then the collection's)."""
    try:
        data = json.loads(path.read_text(encoding='utf-8')) if path else {}
    except (OSError, ValueError):
        return {}
    return {str(k): float(v) for k, v in data.items()} if isinstance(data, dict) else {}


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> LongTestsFirst | None:
    prefixes = tuple(config.getini(LONG_TESTS_INI))
    if config.getoption('dist') != 'load' or not (prefixes or config.getini(DURATIONS_INI)):
        return None
    scheduler = LongTestsFirst(worker_count(config.getoption('tx')), prefixes, config,
                               read_durations(durations_path(config)))
    config.stash[SCHEDULER] = scheduler
    return scheduler


def pytest_sessionfinish(session: pytest.Session) -> None:
    """With ``--record-test-durations``, write what this run measured (the controller)."""
    config = session.config
    scheduler = config.stash.get(SCHEDULER, None)
    path = durations_path(config)
    if scheduler is None or path is None or not config.getoption(RECORD_OPTION):
        return
    measured = {rig: round(seconds, 1) for rig, seconds in sorted(scheduler.measured.items())}
    path.write_text(json.dumps(measured, indent=0) + '\n', encoding='utf-8')


SCHEDULER = pytest.StashKey['LongTestsFirst']()


class LongTestsFirst:
    """xdist ``load`` scheduling, with the tests named by ``long_prefixes`` sent first.

    A long test goes to a worker with at most one test queued (a worker runs a test
    once it knows the next one, so the last one it holds waits for more or for its
    shutdown), and at most ``ceil(workers * LONG_SHARE)`` workers have one while other
    tests are left.
    """

    def __init__(self, expected_workers: int, long_prefixes: Sequence[str],
                 config: pytest.Config | None = None,
                 costs: Mapping[str, float] | None = None) -> None:
        self.expected_workers = expected_workers
        self.long_prefixes = tuple(long_prefixes)
        self.config = config
        #: recorded seconds per class or module (``rig_of``), costliest sent first
        self.costs = dict(costs or {})
        #: the seconds each class or module took in this run
        self.measured: dict[str, float] = {}
        #: each other test's share of its class's or module's recorded cost
        self.test_costs: dict[int, float] = {}
        self.node2collection: dict[Any, list[str]] = {}
        self.node2pending: dict[Any, list[int]] = {}
        self.collection: list[str] | None = None
        #: every other test not yet sent, in collection order
        self.pending: list[int] = []
        #: the long tests not yet sent, in the order of ``long_prefixes``
        self.long_pending: list[int] = []
        self.long_tests: frozenset[int] = frozenset()

    # the scheduling protocol

    @property
    def nodes(self) -> list[Any]:
        return list(self.node2pending)

    @property
    def collection_is_completed(self) -> bool:
        return len(self.node2collection) >= self.expected_workers

    @property
    def tests_finished(self) -> bool:
        if not self.collection_is_completed or self.pending or self.long_pending:
            return False
        return all(len(queued) < 2 for queued in self.node2pending.values())

    @property
    def has_pending(self) -> bool:
        return bool(self.pending or self.long_pending
                    or any(self.node2pending.values()))

    def add_node(self, node: Worker) -> None:
        assert node not in self.node2pending
        self.node2pending[node] = []

    def add_node_collection(self, node: Worker, collection: Sequence[str]) -> None:
        if self.collection is not None and list(collection) != self.collection:
            self.collection_differs(node)
            return
        self.node2collection[node] = list(collection)

    def mark_test_complete(self, node: Worker, item_index: int, duration: float = 0) -> None:
        self.node2pending[node].remove(item_index)
        if self.collection is not None:
            rig = rig_of(self.collection[item_index])
            self.measured[rig] = self.measured.get(rig, 0.0) + duration
        self.check_schedule(node, duration)

    def mark_test_pending(self, item: str) -> None:
        assert self.collection is not None
        self.pending.insert(0, self.collection.index(item))
        for node in self.nodes:
            self.check_schedule(node)

    def remove_pending_tests_from_node(self, node: Worker, indices: Sequence[int]) -> None:
        raise NotImplementedError('only work stealing takes tests back')

    def remove_node(self, node: Worker) -> str | None:
        """A worker that ended: its queued tests go to the others; the one it was running
        (the first queued) is the crashed one, as xdist's schedulers report it."""
        queued = self.node2pending.pop(node)
        if not queued:
            return None
        assert self.collection is not None
        crashed = self.collection[queued.pop(0)]
        self.pending.extend(queued)
        for other in self.nodes:
            self.check_schedule(other)
        return crashed

    def schedule(self) -> None:
        if self.collection is not None:
            for node in self.nodes:
                self.check_schedule(node)
            return
        collections = list(self.node2collection.values())
        if any(collection != collections[0] for collection in collections[1:]):
            self.collection_differs(next(iter(self.node2collection)))
            return
        self.collection = collections[0]
        rank: dict[int, int] = {}
        for index, nodeid in enumerate(self.collection):
            listed = [n for n, prefix in enumerate(self.long_prefixes) if nodeid.startswith(prefix)]
            if listed:
                rank[index] = listed[0]
        self.long_pending = sorted(rank, key=lambda index: (rank[index], index))
        self.long_tests = frozenset(rank)
        self.pending = self.costliest_first(
            [i for i in range(len(self.collection)) if i not in self.long_tests])
        chunk = max(2, len(self.collection) // max(1, len(self.nodes)) // 4)
        for node in self.nodes:
            if not self.send_long_test(node):
                self.send(node, self.take(chunk))
        if not self.pending and not self.long_pending:
            for node in self.nodes:
                node.shutdown()

    # the policy

    def costliest_first(self, indices: list[int]) -> list[int]:
        """``indices`` by class or module, the costliest recorded first, each one's tests
        together and in collection order; the ones not recorded last, in collection order."""
        assert self.collection is not None
        rigs = {index: rig_of(self.collection[index]) for index in indices}
        first: dict[str, int] = {}
        tests: dict[str, int] = {}
        for index in indices:
            first.setdefault(rigs[index], index)
            tests[rigs[index]] = tests.get(rigs[index], 0) + 1
        self.test_costs = {i: self.costs.get(rigs[i], 0.0) / tests[rigs[i]] for i in indices}
        return sorted(indices, key=lambda i: (-self.costs.get(rigs[i], 0.0), first[rigs[i]], i))

    @property
    def long_limit(self) -> int:
        return max(1, math.ceil(len(self.node2pending) * LONG_SHARE))

    def long_tests_out(self) -> int:
        """How many workers have long tests queued."""
        return sum(any(index in self.long_tests for index in queued)
                   for queued in self.node2pending.values())

    def check_schedule(self, node: Worker, duration: float = 0) -> None:
        """Give ``node`` more tests if it runs low, as xdist's ``load`` does: a long test
        first if one is left and may go out, else a chunk of the others."""
        if node.shutting_down:
            return
        if not self.send_long_test(node) and self.pending:
            queued = self.node2pending[node]
            per_node = len(self.pending) // len(self.node2pending)
            low, high = max(2, per_node // 4), max(2, per_node // 2)
            # xdist's heuristic: a worker on long tests that still has two waits for them
            if len(queued) < low and not (duration >= 0.1 and len(queued) >= 2):
                self.send(node, self.take_chunk(high - len(queued), 2 - len(queued)))
        if not self.pending and not self.long_pending:
            node.shutdown()

    def send_long_test(self, node: Worker) -> bool:
        """Send ``node`` the next long test if it has at most one test queued and
        the limit allows; once the other tests are all out, there is no limit (nothing is
        left to keep going beside them, and a worker holding its last test would wait)."""
        queued = self.node2pending[node]
        if not self.long_pending or len(queued) > 1:
            return False
        if self.pending and self.long_tests_out() >= self.long_limit:
            return False
        self.send(node, [self.long_pending.pop(0), *self.take(1 - len(queued))])
        return True

    def take_chunk(self, count: int, at_least: int) -> list[int]:
        """Up to ``count`` other tests, fewer where their recorded cost passes half of a
        worker's share of what is left (xdist's ``load`` counts tests only, and a worker
        that took a chunk of 25 tests worth 40 s near the end ran alone for 40 s after the
        others had finished), but at least ``at_least`` (a worker runs its last queued test
        only once it has another)."""
        budget = sum(self.test_costs.get(i, 0.0) for i in self.pending) / len(
            self.node2pending) / 2
        spent, size = 0.0, 0
        for index in self.pending[:count]:
            spent += self.test_costs.get(index, 0.0)
            if size >= max(1, at_least) and spent > budget:
                break
            size += 1
        return self.take(size)

    def take(self, count: int) -> list[int]:
        """The next ``count`` other tests (none for a count below one)."""
        count = max(0, count)
        taken, self.pending[:count] = self.pending[:count], []
        return taken

    def send(self, node: Worker, indices: list[int]) -> None:
        if indices:
            self.node2pending[node].extend(indices)
            node.send_runtest_some(indices)

    def collection_differs(self, node: Worker) -> None:
        """Fail the run as xdist does when its workers collected different tests."""
        if self.config is not None:
            self.config.hook.pytest_collectreport(report=pytest.CollectReport(
                nodeid=str(getattr(getattr(node, 'gateway', None), 'id', node)),
                outcome='failed', longrepr='the xdist workers collected different tests',
                result=[]))
