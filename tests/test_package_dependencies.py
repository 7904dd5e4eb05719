"""Every package.xml declares, by its rosdep key, what the package's Python code imports.

`rosdep install --from-paths src` on a full ROS 2 install brings exactly what package.xml
declares, so an import without a declaration works here (the venv has everything) and
fails on a robot. The imports are read from the code (ast): package code and launch files
need ``exec_depend``/``depend``, test code (``test/``, and the ``testing/``
helper module trees packages ship for tests) at least ``test_depend``. Third-party modules map
to the keys of rosdistro's rosdep/python.yaml (docs/development.md lists them); a module this table
does not know fails the test, so a new dependency gets its key chosen on purpose.
"""

from __future__ import annotations

import ast
import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parent.parent / 'src'
PACKAGES = sorted(p.parent for p in SRC.glob('*/package.xml'))

# Python module -> rosdep key (rosdistro rosdep/python.yaml; checked against its
# Debian/Ubuntu package names, see the rosdep table in docs/development.md).
THIRD_PARTY = {
    'can': 'python3-can',          # python-can
    'serial': 'python3-serial',    # pyserial
    'yaml': 'python3-yaml',        # PyYAML
    'numpy': 'python3-numpy',
    'hid': 'python3-hidapi',       # PyPI hidapi (cython-hidapi) = Debian python3-hid
    'pytest': 'python3-pytest',
    'hypothesis': 'python3-hypothesis',
    'urdf_parser_py': 'urdfdom_py',  # a ROS package in Jazzy, not a python3-* key
    # rosdep/python.yaml has pymap3d-pip (pip) and no python3-pymap3d key, although
    # Debian ships python3-pymap3d (bookworm: 2.9.1)
    'pymap3d': 'pymap3d-pip',
    'geographiclib': 'python3-geographiclib',  # Debian/Ubuntu python3-geographiclib
}
# Imported by setup.py only (build time, brought by colcon itself).
BUILD_ONLY = {'setuptools'}
# gimbal_msgs' tests use gimbal_driver_common's process helpers; declaring that would make
# a cycle (gimbal_driver_common depends on gimbal_msgs) that colcon refuses to order.
CYCLES = {('gimbal_msgs', 'gimbal_driver_common')}


def imported_modules(path: Path) -> set[str]:
    """Top-level names of the absolute imports of one file."""
    tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name.split('.')[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.split('.')[0])
    return found


def declared(package: Path) -> tuple[set[str], set[str]]:
    """(run-time keys, test keys) of a package.xml."""
    root = ET.parse(package / 'package.xml').getroot()
    run = {e.text.strip() for e in root if e.tag in ('depend', 'exec_depend')}
    test = {e.text.strip() for e in root if e.tag == 'test_depend'}
    return run, run | test


def rosdep_key(module: str, workspace: set[str]) -> str | None:
    """The key that brings ``module``; None for the standard library and this package."""
    if module in sys.stdlib_module_names or module in BUILD_ONLY:
        return None
    if module in THIRD_PARTY:
        return THIRD_PARTY[module]
    if module in workspace or _is_ros_package(module):
        return module
    raise AssertionError(f'import {module}: no rosdep key known; add it to THIRD_PARTY '
                         '(and the table in docs/development.md) after looking it up in rosdistro')


def _is_ros_package(module: str) -> bool:
    """A ROS package's Python module (installed under share/<name>/package.xml; launch and
    launch_ros are not on PyPI, so not in this environment)."""
    return any(Path(prefix, 'share', module, 'package.xml').is_file()
               for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
               if prefix) or module in {'launch', 'launch_ros', 'launch_testing'}


@pytest.mark.parametrize('package', PACKAGES, ids=[p.name for p in PACKAGES])
def test_package_xml_declares_every_import(package: Path):
    workspace = {p.name for p in PACKAGES}
    run, run_and_test = declared(package)
    missing = []
    for path in sorted(package.rglob('*.py')):
        relative = path.relative_to(package)
        # Test helpers shipped in a package (a testing/ module tree) serve tests only.
        is_test = relative.parts[0] == 'test' or 'testing' in relative.parts[:-1]
        local = {p.stem for p in path.parent.glob('*.py')}  # test helpers beside the file
        for module in sorted(imported_modules(path) - local):
            key = rosdep_key(module, workspace)
            if key is None or key == package.name or (package.name, key) in CYCLES:
                continue
            if key not in (run_and_test if is_test else run):
                kind = 'test_depend' if is_test else 'exec_depend'
                missing.append(f'{relative}: import {module} needs <{kind}>{key}</{kind}>')
    assert not missing, '\n'.join(missing)


def test_launch_files_dependencies_are_declared():
    """`ros2 launch` needs launch and launch_ros from rosdep, whatever the files import."""
    for package in PACKAGES:
        if list(package.glob('launch/*.launch.py')):
            run, _ = declared(package)
            assert {'launch', 'launch_ros'} <= run, package.name


@pytest.mark.parametrize('package', PACKAGES, ids=[p.name for p in PACKAGES])
def test_package_xml_is_valid_for_rosdep_and_colcon(package: Path):
    """catkin_pkg (what rosdep and colcon parse package.xml with) accepts the manifest."""
    catkin_package = pytest.importorskip('catkin_pkg.package')
    manifest = catkin_package.parse_package(package / 'package.xml')
    manifest.validate()
    assert manifest.name == package.name
