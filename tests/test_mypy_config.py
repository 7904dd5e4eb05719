"""mypy finds every package under src/ by itself: a new package is type-checked with no
edit to mypy.ini (issue: the sixth driver touched mypy.ini's hand-kept package list).

The file set is mypy's own: mypy.ini parsed by mypy's config parser and the sources it
resolves from ``files`` and ``exclude`` (what a bare ``mypy`` in the root checks), with
the module name mypy gives each file.
"""

from __future__ import annotations

import configparser
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: the one package left out on purpose (mypy.ini says why)
UNCHECKED = {'gimbal_driver_testing'}


def mypy_sources(root: Path) -> dict[str, str]:
    """Source path (relative to ``root``) -> module name, as ``mypy`` run in ``root`` with
    its mypy.ini resolves them."""
    from mypy.config_parser import parse_config_file
    from mypy.find_sources import create_source_list
    from mypy.options import Options

    options = Options()
    parse_config_file(options, lambda: None, str(root / 'mypy.ini'))
    sources = create_source_list(options.files or [], options)
    return {Path(source.path).resolve().relative_to(root).as_posix(): source.module
            for source in sources if source.path}


def python_packages(root: Path) -> list[Path]:
    """src/<pkg>/<pkg>/ of every ament_python package (package.xml and setup.py)."""
    return sorted(p.parent / p.parent.name for p in (root / 'src').glob('*/setup.py')
                  if (p.parent / 'package.xml').is_file())


@pytest.fixture()
def in_root(monkeypatch):
    """mypy resolves ``files`` against the working directory, as when run in the root."""
    def enter(root: Path) -> dict[str, str]:
        monkeypatch.chdir(root)
        return mypy_sources(root)
    return enter


def test_every_module_of_every_package_is_checked(in_root) -> None:
    sources = in_root(ROOT)
    packages = python_packages(ROOT)
    assert {p.name for p in packages} >= {'gimbal_driver_common', 'virtual_gimbal_driver'}
    for package in packages:
        modules = sorted(package.rglob('*.py'))
        assert modules, package
        for module in modules:
            relative = module.relative_to(ROOT).as_posix()
            if package.name in UNCHECKED:
                assert relative not in sources, f'{relative}: mypy.ini says it is left out'
                continue
            dotted = '.'.join(module.relative_to(package.parent).with_suffix('').parts)
            assert sources.get(relative) == dotted.removesuffix('.__init__'), relative


def test_tests_launch_files_and_setup_py_are_not_modules_to_check(in_root) -> None:
    for relative in in_root(ROOT):
        parts = relative.split('/')
        assert 'test' not in parts and 'launch' not in parts, relative
        assert parts[-1] != 'setup.py', relative


def test_a_new_package_is_checked_without_an_edit(in_root, tmp_path: Path) -> None:
    """A sixth driver, src/pelco_d_driver, laid out as the checklist says: its modules are
    checked under their own names, its tests, launch file and setup.py are not."""
    shutil.copy(ROOT / 'mypy.ini', tmp_path / 'mypy.ini')
    package = tmp_path / 'src' / 'pelco_d_driver'
    files = {'package.xml': '<package format="3"><name>pelco_d_driver</name></package>\n',
             'setup.py': 'from setuptools import setup\n',
             'pelco_d_driver/__init__.py': '',
             'pelco_d_driver/node.py': 'x: int = 1\n',
             'pelco_d_driver/protocol/__init__.py': '',
             'pelco_d_driver/protocol/codec.py': 'y: int = 2\n',
             'launch/pelco_d_driver.launch.py': 'z = 3\n',
             'test/test_codec.py': 'w = 4\n'}
    for relative, text in files.items():
        (package / relative).parent.mkdir(parents=True, exist_ok=True)
        (package / relative).write_text(text, encoding='utf-8')
    assert in_root(tmp_path) == {
        'src/pelco_d_driver/pelco_d_driver/__init__.py': 'pelco_d_driver',
        'src/pelco_d_driver/pelco_d_driver/node.py': 'pelco_d_driver.node',
        'src/pelco_d_driver/pelco_d_driver/protocol/__init__.py': 'pelco_d_driver.protocol',
        'src/pelco_d_driver/pelco_d_driver/protocol/codec.py': 'pelco_d_driver.protocol.codec',
    }


def test_mypy_ini_names_no_package() -> None:
    """No per-package list to keep: neither ``mypy_path`` nor a package in ``files``."""
    parser = configparser.ConfigParser()
    parser.read(ROOT / 'mypy.ini')
    settings = parser['mypy']
    assert 'mypy_path' not in settings
    names = {p.name for p in python_packages(ROOT)} - UNCHECKED
    assert not [name for name in names if name in settings.get('files', '')]
