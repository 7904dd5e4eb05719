"""cpu_report: CPU seconds (the worker's and its reaped children's) and process starts per
test module, and the table docs/testing.md quotes."""

from __future__ import annotations

import json

import pytest

from gimbal_driver_testing.cpu_report import REPORT_ENV, process_name, table

pytest_plugins = ['pytester']

#: a child that runs until it has used 0.3 s of CPU (its own process time)
BURN = "list(iter(lambda: __import__('time').process_time() < 0.3, False))"
SOURCE = f'''
import subprocess, sys

def test_starts_a_busy_child():
    subprocess.run([sys.executable, '-c', {BURN!r}], check=True)

def test_starts_nothing():
    pass
'''


def test_a_module_line_counts_its_tests_children_cpu_and_starts(
        pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> None:
    report = pytester.path / 'cpu.jsonl'
    monkeypatch.setenv(REPORT_ENV, str(report))
    pytester.makepyfile(test_busy=SOURCE, test_idle='def test_idle():\n    pass\n')
    result = pytester.runpytest_subprocess('-p', 'gimbal_driver_testing.cpu_report',
                                           '-p', 'no:cacheprovider')
    result.assert_outcomes(passed=3)
    lines = {line['module']: line
             for line in map(json.loads, report.read_text().splitlines())}
    assert set(lines) == {'test_busy.py', 'test_idle.py'}
    busy, idle = lines['test_busy.py'], lines['test_idle.py']
    assert busy['tests'] == 2 and idle['tests'] == 1
    assert busy['children_s'] >= 0.3  # CPU time of the child: no wall clock in it
    assert busy['started'] == {'python -c': 1} and idle['started'] == {}
    assert idle['children_s'] == 0
    rows = table(list(lines.values())).splitlines()
    assert rows[2].startswith('| `test_busy.py` | 2 |') and '1 python -c' in rows[2]
    assert rows[-1].startswith('| all | 3 |')


def test_without_the_variable_nothing_is_written(pytester: pytest.Pytester,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(REPORT_ENV, raising=False)
    pytester.makepyfile(test_one='def test_one():\n    pass\n')
    result = pytester.runpytest_subprocess('-p', 'gimbal_driver_testing.cpu_report')
    result.assert_outcomes(passed=1)
    assert [p.name for p in pytester.path.iterdir() if p.suffix == '.jsonl'] == []


@pytest.mark.parametrize(('args', 'name'), [
    (['/opt/ros/bin/capture_driver_node', '--ros-args'], 'capture_driver_node'),
    (['/venv/bin/python3', '-m', 'capture_driver.sim', '--port', '1'],
     'python -m capture_driver.sim'),
    (['/venv/bin/python', '/repo/scripts/soak.py', 'capture'], 'python soak.py'),
    (['/venv/bin/python', '-mpytest', '-q'], 'python -m pytest'),
    ('/bin/true', 'true'),
    ([], '?'),
])
def test_a_started_process_is_named_by_what_it_runs(args: object, name: str) -> None:
    assert process_name(args) == name
