"""pytest plugin (opt-in): CPU seconds and process starts per test module.

Load it with ``-p gimbal_driver_testing.cpu_report`` and name a file in
``GIMBAL_CPU_REPORT``; each pytest process (every xdist worker) appends one JSON line per
test module it ran: the module, its tests, the CPU seconds of the worker itself (user +
system, ``RUSAGE_SELF``) and of the processes it started that ended and were reaped
meanwhile (``RUSAGE_CHILDREN``: a node, a simulator, a soak script with the node it
started), and the processes it started (``subprocess.Popen``'s audit event, by name).
A module's time runs from the start of its first test to the end of its last, so its
fixtures' set-up and teardown are its own; a process the module left running and that
ends later is counted where it ends. ``python -m gimbal_driver_testing.cpu_report FILE``
prints the table (docs/testing.md, "Where the time goes").
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time
from collections import Counter
from collections.abc import Generator
from pathlib import Path

import pytest

REPORT_ENV = 'GIMBAL_CPU_REPORT'


def _cpu() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


def process_name(args: object) -> str:
    """What a started process is: the executable, or the script or module python runs."""
    argv = [args] if isinstance(args, (str, bytes, os.PathLike)) else list(args or [])  # type: ignore[call-overload]
    words = [os.fsdecode(a) for a in argv]
    if not words:
        return '?'
    name = Path(words[0]).name
    if name.startswith('python') and len(words) > 1:
        rest = words[1:]
        if rest[0] == '-m' and len(rest) > 1:
            return f'python -m {rest[1]}'
        if rest[0].startswith('-m') and len(rest[0]) > 2:  # python -mpytest
            return f'python -m {rest[0][2:]}'
        return f'python {Path(rest[0]).name}'
    return name


class _Meter:
    def __init__(self, path: str) -> None:
        self.path = path
        self.module = ''
        self.tests = 0
        self.started: Counter[str] = Counter()
        self.start = (0.0, 0.0)
        self.wall = 0.0
        self.began_at = 0.0
        sys.addaudithook(self._audit)

    def _audit(self, event: str, args: tuple) -> None:
        if event == 'subprocess.Popen' and self.module:
            self.started[process_name(args[1])] += 1

    def begin(self, module: str) -> None:
        if module != self.module:
            self.flush()
            self.module, self.tests, self.started = module, 0, Counter()
            self.start, self.wall, self.began_at = _cpu(), time.monotonic(), time.time()
        self.tests += 1

    def flush(self) -> None:
        if not self.module:
            return
        own, children = _cpu()
        line = {
            'module': self.module, 'tests': self.tests,
            'own_s': round(own - self.start[0], 2),
            'children_s': round(children - self.start[1], 2),
            'wall_s': round(time.monotonic() - self.wall, 1),
            'started': dict(self.started), 'pid': os.getpid(),
            'began_at': round(self.began_at, 2), 'ended_at': round(time.time(), 2),
        }
        with open(self.path, 'a', encoding='utf-8') as out:
            out.write(json.dumps(line) + '\n')
        self.module = ''


_meter: _Meter | None = None


def pytest_configure(config: pytest.Config) -> None:
    global _meter
    path = os.environ.get(REPORT_ENV)
    if path and _meter is None:
        _meter = _Meter(path)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Generator:
    if _meter is None:
        return (yield)
    _meter.begin(item.nodeid.split('::')[0])
    try:
        return (yield)
    finally:
        if nextitem is None or nextitem.nodeid.split('::')[0] != _meter.module:
            _meter.flush()


def table(lines: list[dict]) -> str:
    """The markdown table of a report file's lines, the costliest module first."""
    rows: dict[str, dict] = {}
    for line in lines:
        row = rows.setdefault(line['module'], {'tests': 0, 'own_s': 0.0, 'children_s': 0.0,
                                               'wall_s': 0.0, 'started': Counter()})
        for key in ('tests', 'own_s', 'children_s', 'wall_s'):
            row[key] += line[key]
        row['started'].update(line['started'])
    out = ['| module | tests | CPU s (worker + children) | worker | children | wall s '
           '| processes started |', '|---|---|---|---|---|---|---|']
    total = 0.0
    for module, row in sorted(rows.items(), key=lambda kv: -(kv[1]['own_s'] + kv[1]['children_s'])):
        cpu = row['own_s'] + row['children_s']
        total += cpu
        started = ', '.join(f'{n} {name}' for name, n in row['started'].most_common())
        out.append(f"| `{module}` | {row['tests']} | {cpu:.1f} | {row['own_s']:.1f} "
                   f"| {row['children_s']:.1f} | {row['wall_s']:.0f} | {started or '-'} |")
    out.append(f'| all | {sum(r["tests"] for r in rows.values())} | {total:.1f} | | | | |')
    return '\n'.join(out)


if __name__ == '__main__':
    [report] = sys.argv[1:]
    print(table([json.loads(x) for x in Path(report).read_text(encoding='utf-8').splitlines()]))
