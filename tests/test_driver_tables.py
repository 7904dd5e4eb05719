"""The driver tables users read are the registry's drivers (gimbal_driver_common.registry).

README.md's device table, and docs/interface.md's "Packages and executables" and "Drivers
at a glance", list the drivers by hand; a driver registered without its rows (a sixth
package) or a row left after a driver went fails here, naming the row to add or remove.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from gimbal_driver_common.registry import DriverSpec, drivers

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / 'README.md'
INTERFACE = ROOT / 'docs' / 'interface.md'
#: a package linked in a table cell: [pkg](src/pkg/README.md) or [pkg](../src/pkg/README.md)
LINKED = re.compile(r'\[(\w+)\]\((?:\.\./)?src/\1/README\.md\)')


def table(text: str, header: str) -> list[list[str]]:
    """The cells of each body row of the markdown table whose header row starts ``header``."""
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith(header)), None)
    assert start is not None, f'no table with the header {header!r}'
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith('|'):
            break
        rows.append([cell.strip() for cell in line.strip().strip('|').split('|')])
    return rows


def linked_packages(rows: list[list[str]], column: int) -> list[str]:
    return [m.group(1) for row in rows for m in [LINKED.search(row[column])] if m]


def compare(where: str, listed: list[str], specs: list[DriverSpec], row: str) -> list[str]:
    """What to fix: a row to add per registered package missing, one to remove per row of
    a package not registered (``row`` formats the row to add from a spec)."""
    registered = {spec.package: spec for spec in specs}
    problems = [f'{where}: no row for {package} (registered as {spec.name!r}); add '
                f'{row.format(spec=spec)}' for package, spec in registered.items()
                if package not in listed]
    problems += [f'{where}: a row for {package}, which no registration names; remove it or '
                 'register the driver' for package in listed if package not in registered]
    problems += [f'{where}: {package} has {listed.count(package)} rows'
                 for package in sorted(set(listed)) if listed.count(package) > 1]
    return problems


def readme_problems(text: str, specs: list[DriverSpec]) -> list[str]:
    rows = table(text, '| device | package | link |')
    return compare('README.md driver table', linked_packages(rows, 1), specs,
                   '| {spec.title} | [{spec.package}](src/{spec.package}/README.md) | <link> |')


def executables_problems(text: str, specs: list[DriverSpec]) -> list[str]:
    rows = table(text, '| package | executables')
    listed = {row[0].strip('`'): re.findall(r'`([\w-]+)`', row[1]) for row in rows}
    listed.pop('gimbal_msgs', None)  # interfaces only, no driver
    where = 'docs/interface.md "Packages and executables"'
    problems = compare(where, list(listed), specs, '| `{spec.package}` | '
                       '`{spec.node_executable}`, `{spec.sim_executable}` |')
    for spec in specs:
        if spec.package in listed and listed[spec.package] != [spec.node_executable,
                                                               spec.sim_executable]:
            problems.append(f'{where}: {spec.package} lists {listed[spec.package]}, the '
                            f'registry {[spec.node_executable, spec.sim_executable]}')
    return problems


def glance_problems(text: str, specs: list[DriverSpec]) -> list[str]:
    """Every device driver (the reference virtual gimbal is for developers: not a device)."""
    rows = table(text, '| driver | link |')
    devices = [spec for spec in specs if not spec.is_reference]
    return compare('docs/interface.md "Drivers at a glance"', linked_packages(rows, 0),
                   devices, '| [{spec.package}](../src/{spec.package}/README.md) | <link> | '
                   '<joints> | <presets, scans, homing> | <extras> |')


@pytest.fixture(scope='module')
def specs() -> list[DriverSpec]:
    found = drivers()
    if not found:
        pytest.skip('no driver is registered (make build)')
    return found


def test_the_readme_lists_every_registered_driver(specs: list[DriverSpec]) -> None:
    problems = readme_problems(README.read_text(encoding='utf-8'), specs)
    assert not problems, '\n'.join(problems)


def test_the_interface_lists_every_registered_driver_and_its_executables(
        specs: list[DriverSpec]) -> None:
    text = INTERFACE.read_text(encoding='utf-8')
    problems = executables_problems(text, specs) + glance_problems(text, specs)
    assert not problems, '\n'.join(problems)


def test_a_sixth_driver_without_its_rows_fails_naming_them(specs: list[DriverSpec]) -> None:
    """A registered package the tables do not list (one spec renamed) is named, with the row
    to add; the row of the package it replaced is named for removal."""
    from dataclasses import replace

    sixth = replace(specs[-1], name='pelco_d', package='pelco_d_driver', title='Pelco-D head',
                    node_executable='pelco_d_driver_node', sim_executable='pelco_d_sim')
    others = [*specs[:-1], sixth]
    readme = readme_problems(README.read_text(encoding='utf-8'), others)
    assert readme[0] == ("README.md driver table: no row for pelco_d_driver (registered as "
                         "'pelco_d'); add | Pelco-D head | [pelco_d_driver]"
                         "(src/pelco_d_driver/README.md) | <link> |")
    assert f'a row for {specs[-1].package}, which no registration names' in readme[1]
    text = INTERFACE.read_text(encoding='utf-8')
    missing = executables_problems(text, others)
    assert ('add | `pelco_d_driver` | `pelco_d_driver_node`, `pelco_d_sim` |'
            in missing[0])
    wrong = replace(specs[0], sim_executable='other_sim')
    assert any('lists' in p and 'other_sim' in p
               for p in executables_problems(text, [wrong, *specs[1:]]))
