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
long tests mostly wait). Every other test goes out with its class or module (its rig): one
whole class or module to a worker that holds fewer than two tests, so each rig starts once,
on one worker, and no worker holds work another could have started (xdist's ``load``
chunks split classes between workers and queued several modules on one). The classes and
modules go out costliest first, by the worker seconds each took in a recorded run (the
``test_durations`` ini option names the file; ``pytest --record-test-durations`` writes
it), so the run ends on cheap ones, not on a driver's conformance class handed out late
(one ran 80 s past the others). A class or module the file does not know goes after those
it does, in collection order.

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
        self.check_schedule(node)

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
        for node in self.nodes:
            if not self.send_long_test(node):
                self.send(node, self.take_rigs(2))
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
        for index in indices:
            first.setdefault(rigs[index], index)
        return sorted(indices, key=lambda i: (-self.costs.get(rigs[i], 0.0), first[rigs[i]], i))

    @property
    def long_limit(self) -> int:
        return max(1, math.ceil(len(self.node2pending) * LONG_SHARE))

    def long_tests_out(self) -> int:
        """How many workers have long tests queued."""
        return sum(any(index in self.long_tests for index in queued)
                   for queued in self.node2pending.values())

    def check_schedule(self, node: Worker) -> None:
        """Give ``node`` more tests once it holds fewer than two (it runs its last one
        only when it knows the next): a long test first if one is left and may go out,
        else the next class or module whole, or the cheapest one behind a long test."""
        if node.shutting_down:
            return
        queued = self.node2pending[node]
        if not self.send_long_test(node) and self.pending and len(queued) < 2:
            if queued and queued[-1] in self.long_tests:
                self.send(node, self.take_filler())
            else:
                self.send(node, self.take_rigs(2 - len(queued)))
        if not self.pending and not self.long_pending:
            node.shutdown()

    def send_long_test(self, node: Worker) -> bool:
        """Send ``node`` the next long test if it has at most one test queued and
        the limit allows; once the other tests are all out, there is no limit (nothing is
        left to keep going beside them, and a worker holding its last test would wait).
        A worker with nothing queued gets the cheapest class or module behind it, so that
        the long test starts at once and nothing costly waits for it."""
        queued = self.node2pending[node]
        if not self.long_pending or len(queued) > 1:
            return False
        if self.pending and self.long_tests_out() >= self.long_limit:
            return False
        self.send(node, [self.long_pending.pop(0), *(self.take_filler() if not queued else [])])
        return True

    def take_rigs(self, at_least: int) -> list[int]:
        """The next class or module whole, and the ones after it while fewer than
        ``at_least`` tests are taken.

        One at a time, never a chunk of several: what a worker holds is its own until it
        runs it, and a worker whose chunk held a 45 s class behind the 45 s crash-safety
        module ran 35 s past the others (docs/testing.md, "The order the workers get the
        tests"). Whole, so that its rig starts once, on one worker."""
        taken: list[int] = []
        while self.pending and len(taken) < max(1, at_least):
            rig = rig_of(self.collection_of(self.pending[0]))
            size = 1
            while (size < len(self.pending)
                   and rig_of(self.collection_of(self.pending[size])) == rig):
                size += 1
            taken += self.take(size)
        return taken

    def take_filler(self) -> list[int]:
        """The cheapest recorded class or module left (else the last one), whole: what a
        worker holds behind a long test waits for it."""
        rigs = [rig_of(self.collection_of(index)) for index in self.pending]
        if not rigs:
            return []
        recorded = [rig for rig in rigs if rig in self.costs]
        cheapest = min(recorded, key=lambda rig: self.costs[rig]) if recorded else rigs[-1]
        pairs = list(zip(self.pending, rigs, strict=True))
        self.pending = [index for index, rig in pairs if rig != cheapest]
        return [index for index, rig in pairs if rig == cheapest]

    def collection_of(self, index: int) -> str:
        assert self.collection is not None
        return self.collection[index]

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
