"""Every package.xml declares, by a rosdep key that resolves on Ubuntu 24.04 for Jazzy, what
the package's Python code imports.

`rosdep install --from-paths src` brings exactly what package.xml declares, and the build
farm installs a package's ``exec_depend``s with it and its ``test_depend``s only for its own
tests. So an undeclared import works here (the venv has everything) and fails on a robot.
The imports are read from the code (ast, plus ``importorskip``/``import_module`` of a string):

- installed code needs ``exec_depend``/``depend``: the package's modules and its launch
  files;
- test code (``test/``) needs a run-time or a ``test_depend`` key;
- no runtime package brings a test-only key (pytest, hypothesis, geographiclib, the test
  support package ``gimbal_driver_testing``) with it: only the test support may
  exec-depend on them, everything else declares them ``test_depend``;
- setup.py needs a build key (``buildtool_depend``/``build_depend``/``depend``).

Modules map to keys through MODULE_KEYS, and every key is in ROSDEP_KEYS or JAZZY_PACKAGES
with what it resolves to on noble and which rosdistro file says so (docs/development.md lists
them): a module or key these tables do not know fails, so a new dependency is looked up on
purpose, and no key may resolve to pip (the build farm refuses pip keys).
"""

from __future__ import annotations

import ast
import functools
import re
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / 'src'
PACKAGES = sorted(p.parent for p in SRC.glob('*/package.xml'))

# rosdep key -> (what it installs on Ubuntu 24.04 noble, where rosdistro says so). Read from
# ros/rosdistro (master, 2026-08): rosdep/python.yaml gives e.g. `python3-pymap3d: ubuntu:
# '*': [python3-pymap3d], bionic: null, focal: null`, so noble gets the apt package.
ROSDEP_KEYS: dict[str, tuple[str, str]] = {
    'python3-can': ('python3-can', 'rosdep/python.yaml'),
    'python3-serial': ('python3-serial', 'rosdep/python.yaml'),
    'python3-yaml': ('python3-yaml', 'rosdep/python.yaml'),
    'python3-numpy': ('python3-numpy', 'rosdep/python.yaml'),
    'python3-hidapi': ('python3-hid', 'rosdep/python.yaml'),   # cython-hidapi: hid, hidraw
    'python3-pymap3d': ('python3-pymap3d', 'rosdep/python.yaml'),
    'python3-geographiclib': ('python3-geographiclib', 'rosdep/python.yaml'),
    'python3-pytest': ('python3-pytest', 'rosdep/python.yaml'),
    'python3-pytest-timeout': ('python3-pytest-timeout', 'rosdep/python.yaml'),
    'python3-pytest-xdist': ('python3-pytest-xdist', 'rosdep/python.yaml'),
    'python3-hypothesis': ('python3-hypothesis', 'rosdep/python.yaml'),
    'python3-setuptools': ('python3-setuptools', 'rosdep/python.yaml'),
}
# ROS package key -> its release repository in jazzy/distribution.yaml (ros-jazzy-<name>).
JAZZY_PACKAGES: dict[str, str] = {
    'action_msgs': 'rcl_interfaces', 'builtin_interfaces': 'rcl_interfaces',
    'lifecycle_msgs': 'rcl_interfaces', 'rcl_interfaces': 'rcl_interfaces',
    'diagnostic_msgs': 'common_interfaces', 'geometry_msgs': 'common_interfaces',
    'sensor_msgs': 'common_interfaces', 'std_msgs': 'common_interfaces',
    'std_srvs': 'common_interfaces', 'trajectory_msgs': 'common_interfaces',
    'rclpy': 'rclpy', 'launch': 'launch', 'launch_testing': 'launch',
    'launch_ros': 'launch_ros', 'launch_testing_ros': 'launch_ros',
    'ament_index_python': 'ament_index', 'robot_state_publisher': 'robot_state_publisher',
    'urdfdom_py': 'urdf_parser_py', 'ament_cmake': 'ament_cmake',
    'ament_cmake_pytest': 'ament_cmake',
    'rosidl_default_generators': 'rosidl_defaults', 'rosidl_default_runtime': 'rosidl_defaults',
    'ament_copyright': 'ament_lint', 'ament_flake8': 'ament_lint', 'ament_pep257': 'ament_lint',
}
# Python module -> rosdep key, where the two names differ (a ROS package's module is its name).
MODULE_KEYS: dict[str, str] = {
    'can': 'python3-can',
    'serial': 'python3-serial',
    'yaml': 'python3-yaml',
    'numpy': 'python3-numpy',
    'hid': 'python3-hidapi', 'hidraw': 'python3-hidapi',
    'pymap3d': 'python3-pymap3d',
    'geographiclib': 'python3-geographiclib',
    'pytest': 'python3-pytest',
    'xdist': 'python3-pytest-xdist',
    'hypothesis': 'python3-hypothesis',
    'setuptools': 'python3-setuptools',
    'urdf_parser_py': 'urdfdom_py',
}
# importlib.import_module(<a variable>) cannot be read from the code: each such file and the
# modules it may load. usb_link.USB_BACKENDS: cython-hidapi's hidraw and hid (libusb);
# registry: driver modules named by the installed entry points (workspace packages).
DYNAMIC_IMPORTS: dict[str, set[str]] = {
    'kessler_kos_driver/kessler_kos_driver/usb_link.py': {'hid', 'hidraw'},
    'gimbal_driver_common/gimbal_driver_common/registry.py': set(),
    # every interface of gimbal_msgs.msg/srv/action, by name
    'gimbal_msgs/test/test_interfaces.py': {'gimbal_msgs'},
    'gimbal_driver_common/test/gimbal_msgs_peer.py': {'gimbal_msgs'},
}
# (package, workspace package) pairs a test may import without declaring it because the
# declaration would be a cycle colcon refuses to order (colcon orders a package after its
# direct dependencies of every kind, test_depend included). test_cycle_exemptions_are_needed
# fails once one is stale. gimbal_driver_common's tests use the harness of
# gimbal_driver_testing, which exec-depends on gimbal_driver_common; scripts/colcon_test.sh
# builds it for them.
CYCLES: set[tuple[str, str]] = {('gimbal_driver_common', 'gimbal_driver_testing')}
#: the package that holds the test support; the one allowed to exec-depend on TEST_ONLY_KEYS
TEST_SUPPORT = 'gimbal_driver_testing'
#: keys only tests need: a robot installing a runtime package must not get them
TEST_ONLY_KEYS = frozenset({'python3-pytest', 'python3-pytest-timeout', 'python3-pytest-xdist',
                            'python3-hypothesis',
                            'python3-geographiclib', TEST_SUPPORT})

RUN = ('depend', 'exec_depend')
TEST = (*RUN, 'test_depend')
BUILD = ('depend', 'build_depend', 'buildtool_depend')


def declared(package: Path) -> dict[str, set[str]]:
    """Dependency tag -> keys of a package.xml."""
    tags: dict[str, set[str]] = {}
    for element in ET.parse(package / 'package.xml').getroot():
        if element.tag.endswith('depend') and element.text:
            tags.setdefault(element.tag, set()).add(element.text.strip())
    return tags


def keys_of(package: Path, kinds: tuple[str, ...]) -> set[str]:
    tags = declared(package)
    return set().union(*(tags.get(kind, set()) for kind in kinds))


def kind_of(relative: Path) -> tuple[str, ...]:
    """The dependency tags that cover a file's imports (see the module docstring)."""
    if relative.parts[0] == 'test':
        return TEST
    if relative.as_posix() == 'setup.py':
        return BUILD
    return RUN


def imports(path: Path) -> tuple[str, ...]:
    """Dotted names of the absolute imports of one file, string imports included. Parsed
    once per content (the closure walk reads each module again for every test file: the
    module's tests took 9.8 s of CPU parsing the same files)."""
    stat = path.stat()
    return parsed_imports(path, stat.st_mtime_ns, stat.st_size)


@functools.cache
def parsed_imports(path: Path, mtime_ns: int, size: int) -> tuple[str, ...]:
    """:func:`imports` of ``path`` as it is at ``mtime_ns`` and ``size``."""
    tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append(node.module)
            names.extend(f'{node.module}.{alias.name}' for alias in node.names)
        elif (isinstance(node, ast.Call) and node.args
              and getattr(node.func, 'attr', getattr(node.func, 'id', None))
              in ('importorskip', 'import_module', '__import__')):
            if isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str):
                names.append(node.args[0].value)
            else:
                names.append('<dynamic>')
    return tuple(names)


def rosdep_key(module: str) -> str | None:
    """The key that brings top-level ``module``; None for the standard library."""
    if module in sys.stdlib_module_names:
        return None
    if module in MODULE_KEYS:
        return MODULE_KEYS[module]
    if module in JAZZY_PACKAGES:
        return module
    raise LookupError(f'import {module}: no rosdep key known; look it up in rosdistro and add '
                      'it to MODULE_KEYS/ROSDEP_KEYS (and the table in docs/development.md)')


def undeclared(package: Path, workspace: Mapping[str, Path],
               cycles: set[tuple[str, str]] = CYCLES) -> list[str]:
    """Imports of ``package`` no declaration of the right kind covers, as messages."""
    covered = {kinds: keys_of(package, kinds) for kinds in (RUN, TEST, BUILD)}
    missing = []
    for path in sorted(package.rglob('*.py')):
        relative = path.relative_to(package)
        kinds = kind_of(relative)
        local = {p.stem for p in path.parent.glob('*.py')}   # test helpers beside the file
        names = {name.split('.')[0] for name in imports(path)}
        if '<dynamic>' in names:
            listed = path.relative_to(package.parent).as_posix()
            if listed not in DYNAMIC_IMPORTS:
                missing.append(f'{relative}: a dynamic import; list its modules in '
                               'DYNAMIC_IMPORTS')
            names = (names - {'<dynamic>'}) | DYNAMIC_IMPORTS.get(listed, set())
        for module in sorted(names - local):
            if module == package.name or (package.name, module) in cycles:
                continue
            try:
                key = module if module in workspace else rosdep_key(module)
            except LookupError as exc:
                missing.append(f'{relative}: {exc}')
                continue
            if key is not None and key not in covered[kinds]:
                missing.append(f'{relative}: import {module} needs <{kinds[-1]}>{key}'
                               f'</{kinds[-1]}> (or {", ".join(kinds[:-1])})')
    return missing


def workspace_of(packages: list[Path]) -> dict[str, Path]:
    return {p.name: p for p in packages}


def exec_closure(name: str, workspace: Mapping[str, Path]) -> set[str]:
    """Keys installed with workspace package ``name``: its run keys and theirs, recursively."""
    seen: set[str] = set()
    todo = [name]
    while todo:
        for key in keys_of(workspace[todo.pop()], RUN) - seen:
            seen.add(key)
            if key in workspace:
                todo.append(key)
    return seen


def prefixes(dotted: str) -> list[str]:
    parts = dotted.split('.')
    return ['.'.join(parts[:i]) for i in range(1, len(parts) + 1)]


def module_file(dotted: str, workspace: Mapping[str, Path]) -> Path | None:
    """The source file of a workspace module (``pkg/pkg/a/b.py`` or ``.../b/__init__.py``)."""
    parts = dotted.split('.')
    if parts[0] not in workspace:
        return None
    base = workspace[parts[0]].joinpath(*parts)
    for candidate in (base.with_suffix('.py'), base / '__init__.py'):
        if candidate.is_file():
            return candidate
    return None


def closure_gaps(package: Path, workspace: Mapping[str, Path],
                 cycles: set[tuple[str, str]] = CYCLES) -> list[str]:
    """Third-party modules a package's tests reach through other workspace packages' modules
    (e.g. gimbal_driver_testing.look_at_geo -> geographiclib) that are not installed
    for those tests: the package's own run/test keys and the exec closure of its workspace
    dependencies."""
    installed = keys_of(package, TEST)
    for key in list(installed):
        if key in workspace:
            installed |= exec_closure(key, workspace)
    skip = {package.name} | {other for name, other in cycles if name == package.name}
    gaps: set[str] = set()
    for test_file in sorted((package / 'test').rglob('*.py')):
        seen: set[Path] = set()
        todo = [prefix for name in imports(test_file) if name.split('.')[0] not in skip
                for prefix in prefixes(name)]
        while todo:
            dotted = todo.pop()
            found = module_file(dotted, workspace)
            if found is None or found in seen:
                continue
            seen.add(found)
            for name in imports(found):
                top = name.split('.')[0]
                if top in skip:
                    continue
                if top in workspace:
                    todo.extend(prefixes(name))   # a package's __init__ runs first
                    continue
                try:
                    key = rosdep_key(top) if top != '<dynamic>' else None
                except LookupError:
                    continue   # reported by undeclared() for the package that imports it
                if key is not None and key not in installed:
                    where = found.relative_to(workspace[dotted.split('.')[0]].parent)
                    gaps.add(f'{test_file.relative_to(package)}: {where.as_posix()} '
                             f'imports {top} ({key}), not installed for these tests')
    return sorted(gaps)


def runtime_test_keys(package: Path, workspace: Mapping[str, Path]) -> list[str]:
    """The test-only keys installed with runtime package ``package`` (its exec closure), as
    messages; none for the test support itself."""
    if package.name == TEST_SUPPORT:
        return []
    return [f'{package.name}: <exec_depend>{key}</exec_depend> (directly or through a workspace '
            'package) is test-only; declare it <test_depend>'
            for key in sorted(exec_closure(package.name, workspace) & TEST_ONLY_KEYS)]


IDS = [p.name for p in PACKAGES]


@pytest.mark.parametrize('package', PACKAGES, ids=IDS)
def test_no_runtime_package_brings_test_tools(package: Path):
    gaps = runtime_test_keys(package, workspace_of(PACKAGES))
    assert not gaps, '\n'.join(gaps)


def test_the_test_support_is_a_package_the_drivers_test_depend_on():
    workspace = workspace_of(PACKAGES)
    assert TEST_SUPPORT in workspace
    drivers = [p for p in PACKAGES if p.name.endswith('_driver')]
    assert drivers and all(TEST_SUPPORT in keys_of(p, ('test_depend',)) for p in drivers)


@pytest.mark.parametrize('package', PACKAGES, ids=IDS)
def test_package_xml_declares_every_import(package: Path):
    missing = undeclared(package, workspace_of(PACKAGES))
    assert not missing, '\n'.join(missing)


@pytest.mark.parametrize('package', PACKAGES, ids=IDS)
def test_tests_get_what_they_import_through_other_packages(package: Path):
    gaps = closure_gaps(package, workspace_of(PACKAGES))
    assert not gaps, '\n'.join(gaps)


@pytest.mark.parametrize('package', PACKAGES, ids=IDS)
def test_every_key_resolves_on_noble_for_jazzy(package: Path):
    """Each declared key is a workspace package, a Jazzy ROS package, or a rosdep key that
    resolves to an apt package on noble (not pip, not nothing)."""
    workspace = workspace_of(PACKAGES)
    for tag, keys in declared(package).items():
        for key in keys:
            assert key in workspace or key in JAZZY_PACKAGES or key in ROSDEP_KEYS, (
                f'<{tag}>{key}: not checked against rosdistro; add it to ROSDEP_KEYS or '
                'JAZZY_PACKAGES after reading its entry')
            assert not key.endswith('-pip'), f'<{tag}>{key}: pip keys are refused on the farm'


def test_tables_name_apt_packages():
    for key, (apt, source) in ROSDEP_KEYS.items():
        assert re.fullmatch(r'python3-[a-z0-9.-]+', apt), (key, apt)
        assert source in ('rosdep/python.yaml', 'rosdep/base.yaml'), key
    assert set(MODULE_KEYS.values()) <= set(ROSDEP_KEYS) | set(JAZZY_PACKAGES)


def test_launch_files_dependencies_are_declared():
    """`ros2 launch` needs launch and launch_ros from rosdep, whatever the files import."""
    for package in PACKAGES:
        if list(package.glob('launch/*.launch.py')):
            assert {'launch', 'launch_ros'} <= keys_of(package, RUN), package.name


def test_docs_list_every_declared_key():
    """docs/development.md's rosdep table names every key a package.xml declares."""
    text = (ROOT / 'docs' / 'development.md').read_text(encoding='utf-8')
    table = text.split('### rosdep keys', 1)[1].split('\n#', 1)[0]
    documented = {key for row in table.splitlines() if row.startswith('| `')
                  for key in re.findall(r'`([^`]+)`', row.split('|')[1])}
    workspace = workspace_of(PACKAGES)
    used = {key for p in PACKAGES for keys in declared(p).values() for key in keys}
    assert sorted(used - set(workspace) - documented) == []


def test_cycle_exemptions_are_needed():
    """An exemption stays only while the package's tests still import the other package."""
    for package, other in CYCLES:
        names = {name.split('.')[0] for path in (SRC / package).rglob('*.py')
                 for name in imports(path)}
        assert other in names, f'({package}, {other}) is no longer needed: remove it'


@pytest.mark.parametrize('package', PACKAGES, ids=IDS)
def test_package_xml_is_valid_for_rosdep_and_colcon(package: Path):
    """catkin_pkg (what rosdep and colcon parse package.xml with) accepts the manifest."""
    catkin_package = pytest.importorskip('catkin_pkg.package')
    manifest = catkin_package.parse_package(package / 'package.xml')
    manifest.validate()
    assert manifest.name == package.name


# --------------------------------------------------------------- the checks can fail

def make_package(root: Path, name: str, depends: str, files: Mapping[str, str]) -> Path:
    package = root / name
    package.mkdir()
    (package / 'package.xml').write_text(
        f'<package format="3"><name>{name}</name>{depends}</package>', encoding='utf-8')
    for relative, code in files.items():
        (package / relative).parent.mkdir(parents=True, exist_ok=True)
        (package / relative).write_text(code, encoding='utf-8')
    return package


def test_an_installed_module_needs_exec_depend(tmp_path: Path):
    """hypothesis as a test_depend does not cover an installed module."""
    package = make_package(tmp_path, 'pkg', '<test_depend>python3-hypothesis</test_depend>', {
        'pkg/refused.py': 'import hypothesis\n',
        'test/test_a.py': 'from hypothesis import given\n',
    })
    missing = undeclared(package, {'pkg': package})
    assert missing == ['pkg/refused.py: import hypothesis needs '
                       '<exec_depend>python3-hypothesis</exec_depend> (or depend)']


def test_a_runtime_package_that_brings_a_test_tool_fails(tmp_path: Path):
    """Directly, or through a workspace package it exec-depends on; the test support may."""
    support = make_package(tmp_path, TEST_SUPPORT,
                           '<exec_depend>python3-pytest</exec_depend>', {})
    direct = make_package(tmp_path, 'direct', '<exec_depend>python3-hypothesis</exec_depend>'
                          '<test_depend>python3-pytest</test_depend>', {})
    through = make_package(tmp_path, 'through',
                           f'<exec_depend>{TEST_SUPPORT}</exec_depend>', {})
    fine = make_package(tmp_path, 'fine', f'<test_depend>{TEST_SUPPORT}</test_depend>', {})
    workspace = workspace_of([support, direct, through, fine])
    assert runtime_test_keys(support, workspace) == []
    assert runtime_test_keys(fine, workspace) == []
    assert [m.split(' (')[0] for m in runtime_test_keys(direct, workspace)] == [
        'direct: <exec_depend>python3-hypothesis</exec_depend>']
    assert [m.split(' (')[0] for m in runtime_test_keys(through, workspace)] == [
        f'through: <exec_depend>{TEST_SUPPORT}</exec_depend>',
        'through: <exec_depend>python3-pytest</exec_depend>']


def test_a_fabricated_import_is_caught(tmp_path: Path):
    package = make_package(tmp_path, 'pkg', '<exec_depend>rclpy</exec_depend>', {
        'pkg/node.py': 'import rclpy\nimport fabricated_module_xyz\n',
        'test/test_a.py': 'import pytest\n',
        'setup.py': 'from setuptools import setup\n',
        'pkg/lazy.py': 'import importlib\nimportlib.import_module(name)\n',
    })
    missing = undeclared(package, {'pkg': package})
    assert any('import fabricated_module_xyz: no rosdep key known' in m for m in missing)
    assert 'test/test_a.py: import pytest needs <test_depend>python3-pytest</test_depend> ' \
           '(or depend, exec_depend)' in missing
    assert any(m.startswith('setup.py: import setuptools needs') for m in missing)
    assert any(m.startswith('pkg/lazy.py: a dynamic import') for m in missing)
    assert len(missing) == 4


def test_a_workspace_package_and_a_cycle(tmp_path: Path):
    base = make_package(tmp_path, 'base', '', {'base/__init__.py': ''})
    user = make_package(tmp_path, 'user', '', {'test/test_a.py': 'import base\n'})
    workspace = {'base': base, 'user': user}
    assert undeclared(user, workspace) == [
        'test/test_a.py: import base needs <test_depend>base</test_depend> '
        '(or depend, exec_depend)']
    assert undeclared(user, workspace, cycles={('user', 'base')}) == []


def test_a_test_depend_of_another_package_is_not_installed_for_my_tests(tmp_path: Path):
    """The geographiclib case: the helper's package declares it for its own tests only."""
    helper = make_package(tmp_path, 'helper', '<test_depend>python3-geographiclib</test_depend>',
                          {'helper/__init__.py': '',
                           'helper/testing/__init__.py': '',
                           'helper/testing/geo.py': 'from geographiclib.geodesic import G\n'})
    driver = make_package(tmp_path, 'driver', '<test_depend>helper</test_depend>', {
        'test/test_geo.py': 'from helper.testing.geo import G\n'})
    workspace = {'helper': helper, 'driver': driver}
    gap = ('test/test_geo.py: helper/helper/testing/geo.py imports geographiclib '
           '(python3-geographiclib), not installed for these tests')
    assert closure_gaps(driver, workspace) == [gap]
    # declared where the installed module imports it, it reaches the driver's tests
    (helper / 'package.xml').write_text('<package format="3"><name>helper</name><exec_depend>'
                                        'python3-geographiclib</exec_depend></package>')
    assert closure_gaps(driver, workspace) == []
