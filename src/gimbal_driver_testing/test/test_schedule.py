"""The xdist scheduler that sends the long tests first (gimbal_driver_testing.schedule):
against stand-in workers that run what they are sent as xdist's do, and through xdist."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path

import pytest

from gimbal_driver_testing.schedule import (
    LongTestsFirst,
    read_durations,
    rig_of,
    worker_count,
)

pytest_plugins = ['pytester']

LONG = ('tests/test_new_driver.py::test_builds', 'tests/test_soak.py::')


class StandInWorker:
    """A worker as xdist's remote end treats what it is sent: it runs its queued tests in
    order, and the last one only once it has another or has been told to shut down (pytest
    needs the next item to tear fixtures down)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.shutting_down = False
        self.queued: list[int] = []
        self.ran: list[int] = []

    def send_runtest_some(self, indices: Sequence[int]) -> None:
        assert not self.shutting_down, f'{self.name} was sent tests after its shutdown'
        self.queued.extend(indices)

    def shutdown(self) -> None:
        self.shutting_down = True

    def can_run(self) -> bool:
        return len(self.queued) > 1 or (len(self.queued) == 1 and self.shutting_down)


def collection() -> list[str]:
    return ([f'src/a/test/test_conformance.py::TestA::test_{n}' for n in range(40)]
            + [f'src/b/test/test_node.py::test_{n}' for n in range(20)]
            + ['tests/test_new_driver.py::test_copy', 'tests/test_new_driver.py::test_builds']
            + [f'tests/test_soak.py::test_soak[{d}]' for d in ('a', 'b', 'c')]
            + [f'tests/test_threads.py::test_{n}' for n in range(10)])


def started(workers: int, costs: dict[str, float] | None = None,
            long_prefixes: Sequence[str] = LONG) -> tuple[LongTestsFirst, list[StandInWorker]]:
    scheduler = LongTestsFirst(workers, long_prefixes, costs=costs)
    nodes = [StandInWorker(f'gw{n}') for n in range(workers)]
    for node in nodes:
        scheduler.add_node(node)
    for node in nodes:
        assert not scheduler.collection_is_completed
        scheduler.add_node_collection(node, collection())
    assert scheduler.collection_is_completed
    scheduler.schedule()
    return scheduler, nodes


def run_to_the_end(scheduler: LongTestsFirst, nodes: list[StandInWorker],
                   after_each: Callable[[StandInWorker], None] | None = None) -> None:
    """Let the workers run one test each in turn, reporting each to the scheduler, until
    none can run; ``after_each(worker)`` runs after each report."""
    while any(node.can_run() for node in nodes):
        for node in nodes:
            if node.can_run():
                index = node.queued.pop(0)
                node.ran.append(index)
                scheduler.mark_test_complete(node, index, duration=0.01)
                if after_each is not None:
                    after_each(node)


def names(indices: list[int]) -> list[str]:
    every = collection()
    return [every[i] for i in indices]


@pytest.mark.parametrize('workers', [1, 2, 4, 8])
def test_every_test_runs_once_and_every_worker_is_shut_down(workers: int) -> None:
    scheduler, nodes = started(workers)
    run_to_the_end(scheduler, nodes)
    ran = sorted(i for node in nodes for i in node.ran)
    assert ran == list(range(len(collection())))
    assert all(node.shutting_down and not node.queued for node in nodes)
    assert scheduler.tests_finished
    assert not scheduler.has_pending


def test_the_long_tests_go_first_each_to_a_worker_of_its_own_in_the_listed_order() -> None:
    costs = {'src/a/test/test_conformance.py::TestA': 40.0, 'src/b/test/test_node.py': 20.0,
             'tests/test_threads.py': 1.0, 'tests/test_new_driver.py': 0.5}
    scheduler, nodes = started(8, costs)
    # 3 of the 8 workers: new_driver's build, then the soaks in their order, each with the
    # cheapest class or module left behind it (so it starts at once, and nothing costly
    # waits for it); the next worker gets the costliest class
    assert names(nodes[0].queued) == ['tests/test_new_driver.py::test_builds',
                                      'tests/test_new_driver.py::test_copy']
    assert names(nodes[1].queued) == (['tests/test_soak.py::test_soak[a]']
                                      + [f'tests/test_threads.py::test_{n}' for n in range(10)])
    assert names(nodes[2].queued) == (['tests/test_soak.py::test_soak[b]']
                                      + [f'src/b/test/test_node.py::test_{n}' for n in range(20)])
    assert names(nodes[3].queued) == [f'src/a/test/test_conformance.py::TestA::test_{n}'
                                      for n in range(40)]
    # every other test is out, so the limit is lifted: the last soak goes to the next worker
    assert not scheduler.pending
    assert names(nodes[4].queued) == ['tests/test_soak.py::test_soak[c]']
    assert not any(node.queued for node in nodes[5:])
    run_to_the_end(scheduler, nodes)
    assert sorted(i for node in nodes for i in node.ran) == list(range(len(collection())))


def test_no_more_workers_on_long_tests_than_their_share_while_other_tests_are_left() -> None:
    scheduler, nodes = started(2)
    assert names([nodes[0].queued[0]]) == ['tests/test_new_driver.py::test_builds']
    assert not any(i in scheduler.long_tests for i in nodes[1].queued)
    # after each report: whether other tests were left to send, how many long tests queued
    long_out: list[tuple[bool, int]] = []
    run_to_the_end(scheduler, nodes, lambda node: long_out.append(
        (bool(scheduler.pending), scheduler.long_tests_out())))
    assert {out for others_left, out in long_out if others_left} == {0, 1}
    ran_long = [i for node in nodes for i in node.ran if i in scheduler.long_tests]
    assert sorted(ran_long) == sorted(scheduler.long_tests)


def test_each_class_or_module_goes_whole_to_one_worker_one_at_a_time() -> None:
    """What a worker holds is its own until it runs it: besides the test it runs, a worker
    holds at most one class's or module's tests, and each class's or module's tests all run
    on one worker (its rig starts once)."""
    costs = {'src/a/test/test_conformance.py::TestA': 40.0, 'src/b/test/test_node.py': 2.0,
             'tests/test_threads.py': 1.0}
    scheduler, nodes = started(2, costs, long_prefixes=())
    assert {rig_of(name) for name in names(nodes[0].queued)} == {
        'src/a/test/test_conformance.py::TestA'}
    assert {rig_of(name) for name in names(nodes[1].queued)} == {'src/b/test/test_node.py'}
    held: list[int] = []
    run_to_the_end(scheduler, nodes, lambda node: held.append(
        len({rig_of(name) for name in names(node.queued[1:])})))
    assert max(held) == 1
    ran_on = {rig_of(collection()[i]): {n for n, node in enumerate(nodes) if i in node.ran}
              for i in range(len(collection()))}
    assert all(len(workers) == 1 for workers in ran_on.values())
    assert sorted(nodes[0].ran + nodes[1].ran) == list(range(len(collection())))


def test_a_crashed_worker_names_its_test_and_its_queue_goes_to_the_others() -> None:
    scheduler, nodes = started(2)
    crashed_node = nodes[0]
    queued = list(crashed_node.queued)
    assert scheduler.remove_node(crashed_node) == collection()[queued[0]]
    run_to_the_end(scheduler, nodes[1:])
    assert set(queued[1:]) <= set(nodes[1].ran)


def test_workers_that_collected_different_tests_get_no_test() -> None:
    scheduler = LongTestsFirst(2, LONG)
    nodes = [StandInWorker('gw0'), StandInWorker('gw1')]
    for node in nodes:
        scheduler.add_node(node)
    scheduler.add_node_collection(nodes[0], collection())
    scheduler.add_node_collection(nodes[1], collection()[1:])
    scheduler.schedule()
    assert not nodes[0].queued and not nodes[1].queued
    assert scheduler.tests_finished


def test_recorded_costs_send_the_costliest_class_or_module_first_each_kept_together() -> None:
    costs = {'tests/test_threads.py': 30.0, 'src/b/test/test_node.py': 20.0,
             'src/a/test/test_conformance.py::TestA': 5.0, 'gone/test_old.py': 99.0}
    scheduler, nodes = started(1, costs, long_prefixes=())
    run_to_the_end(scheduler, nodes)
    ran = [rig_of(name) for name in names(nodes[0].ran)]
    # by cost; the soaks' and test_copy's modules were not recorded: last, in collection order
    assert ran == (['tests/test_threads.py'] * 10 + ['src/b/test/test_node.py'] * 20
                   + ['src/a/test/test_conformance.py::TestA'] * 40
                   + ['tests/test_new_driver.py'] * 2 + ['tests/test_soak.py'] * 3)
    assert scheduler.measured['tests/test_threads.py'] == pytest.approx(0.1)


def test_behind_a_long_test_goes_the_cheapest_recorded_class_or_module() -> None:
    costs = {'tests/test_threads.py': 30.0, 'src/b/test/test_node.py': 20.0,
             'src/a/test/test_conformance.py::TestA': 5.0}
    scheduler, nodes = started(1, costs)
    assert names(nodes[0].queued) == (['tests/test_new_driver.py::test_builds']
                                      + [f'src/a/test/test_conformance.py::TestA::test_{n}'
                                         for n in range(40)])
    # then the cheapest recorded of those left, and once none is recorded, the last
    assert {rig_of(name) for name in names(scheduler.take_filler())} == {
        'src/b/test/test_node.py'}
    assert {rig_of(name) for name in names(scheduler.take_filler())} == {
        'tests/test_threads.py'}
    assert names(scheduler.take_filler()) == ['tests/test_new_driver.py::test_copy']
    assert scheduler.take_filler() == [] and not scheduler.pending


def test_unreadable_durations_give_no_costs(tmp_path: Path) -> None:
    assert read_durations(None) == {}
    assert read_durations(tmp_path / 'missing.json') == {}
    (tmp_path / 'bad.json').write_text('{not json')
    assert read_durations(tmp_path / 'bad.json') == {}
    (tmp_path / 'list.json').write_text('[1, 2]')
    assert read_durations(tmp_path / 'list.json') == {}


def test_a_rig_is_the_class_or_else_the_module() -> None:
    assert rig_of('src/a/test/test_c.py::TestA::test_x[1]') == 'src/a/test/test_c.py::TestA'
    assert rig_of('tests/test_soak.py::test_soak[capture]') == 'tests/test_soak.py'


def test_worker_count_reads_xdist_tx_specs() -> None:
    assert worker_count(['8*popen']) == 8
    assert worker_count(['popen', '2*popen//python=python3']) == 3


def test_through_xdist_the_long_tests_start_first_on_workers_of_their_own(
        pytester: pytest.Pytester) -> None:
    """Real xdist workers: each long test (two parametrizations of one) is the first test
    its worker runs."""
    pytest.importorskip('xdist', reason='needs pytest-xdist')
    log = pytester.path / 'order.log'
    record = (f'import os\ndef record(name):\n'
              f'    with open({str(log)!r}, "a") as out:\n'
              f'        out.write(os.environ["PYTEST_XDIST_WORKER"] + " " + name + "\\n")\n')
    pytester.makepyfile(record_order=record)
    pytester.makepyfile(test_a='\n'.join(
        ['from record_order import record']
        + [f'def test_{n}():\n    record("a{n}")' for n in range(12)]))
    pytester.makepyfile(test_z_long='\n'.join([
        'import pytest', 'from record_order import record',
        '@pytest.mark.parametrize("n", [0, 1])', 'def test_long(n):',
        '    record(f"long{n}")']))
    pytester.makeini('[pytest]\nlong_tests =\n    test_z_long.py\n')
    result = pytester.runpytest_subprocess(
        '-n', '4', '-p', 'gimbal_driver_testing.schedule', '-p', 'no:cacheprovider')
    result.assert_outcomes(passed=14)
    first_by_worker: dict[str, str] = {}
    for line in Path(log).read_text().splitlines():
        worker, name = line.split()
        first_by_worker.setdefault(worker, name)
    assert sorted(n for n in first_by_worker.values() if n.startswith('long')) == [
        'long0', 'long1']


def test_through_xdist_a_run_records_its_durations_and_a_durations_file_orders_the_next(
        pytester: pytest.Pytester) -> None:
    """``--record-test-durations`` writes each module's seconds; a run with a file that
    makes the last-collected module the costliest sends it first. (The costs are written
    by the test, not measured: which of two quick modules took longer is the machine's.)"""
    pytest.importorskip('xdist', reason='needs pytest-xdist')
    log = pytester.path / 'order.log'
    pytester.makepyfile(record_order=(
        f'def record(name):\n    with open({str(log)!r}, "a") as out:\n'
        f'        out.write(name + "\\n")\n'))
    pytester.makepyfile(test_a='from record_order import record\n' + ''.join(
        f'def test_{n}():\n    record("a")\n' for n in range(6)))
    pytester.makepyfile(test_z='from record_order import record\n' + ''.join(
        f'def test_{n}():\n    record("z")\n' for n in range(2)))
    pytester.makeini('[pytest]\ntest_durations = durations.json\n')
    arguments = ('-n', '1', '-p', 'gimbal_driver_testing.schedule', '-p', 'no:cacheprovider')
    pytester.runpytest_subprocess(*arguments, '--record-test-durations').assert_outcomes(
        passed=8)
    recorded = json.loads((pytester.path / 'durations.json').read_text())
    assert set(recorded) == {'test_a.py', 'test_z.py'}
    assert all(seconds >= 0.0 for seconds in recorded.values())
    assert log.read_text().split() == ['a'] * 6 + ['z'] * 2  # no file yet: collection order
    log.unlink()
    (pytester.path / 'durations.json').write_text(json.dumps({'test_a.py': 0.5,
                                                              'test_z.py': 2.0}))
    pytester.runpytest_subprocess(*arguments).assert_outcomes(passed=8)
    assert log.read_text().split() == ['z'] * 2 + ['a'] * 6
