"""The layers of ARCHITECTURE.md, read from the imports of the code (ast).

- the core's top-level modules are ROS-free (the package docstring says so);
- runtime code never imports the test scaffolding (``gimbal_driver_common.testing``, or a
  driver's own ``<pkg>.testing`` that holds its simulator handle and demo steps): every
  module outside a ``testing`` package is runtime, with no exemption;
- ARCHITECTURE.md names only what exists: every file it names (``<pkg>`` and the like
  stand for each driver) and every ``module.name`` it cites.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / 'src'
CORE = SRC / 'gimbal_driver_common' / 'gimbal_driver_common'
#: top-level modules of ROS client libraries and message packages
ROS_MODULES = ('rclpy', 'launch', 'launch_ros', 'ament_index_python')


def imports(path: Path) -> set[str]:
    """Dotted names of the absolute imports of one file (``from a.b import c`` gives a.b
    and a.b.c, so a check on a package also sees what is imported from it)."""
    tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and (node.module or node.level):
            module = node.module or ''
            if node.level:  # relative: resolved against the file's package under src/<pkg>/
                package = path.relative_to(SRC).parts[1:-1]
                base = '.'.join(package[:len(package) - node.level + 1])
                module = f'{base}.{module}' if module else base
            found.add(module)
            found.update(f'{module}.{alias.name}' for alias in node.names)
    return found


def packages() -> list[str]:
    """The Python package of every ament_python package in ``src/``."""
    return sorted(p.parent.name for p in SRC.glob('*/setup.py'))


def runtime_modules() -> list[Path]:
    """Every installed Python module of every package outside its ``testing`` subpackage."""
    modules = []
    for package in packages():
        root = SRC / package / package
        modules.extend(path for path in sorted(root.rglob('*.py'))
                       if path.relative_to(root).parts[0] != 'testing')
    return modules


def is_scaffolding(name: str) -> bool:
    """Whether a dotted import names a ``testing`` package of ours (or something in one)."""
    return any(name == f'{package}.testing' or name.startswith(f'{package}.testing.')
               for package in packages())


def test_the_core_top_level_is_ros_free() -> None:
    offending = {
        path.name: sorted(name for name in imports(path)
                          if name.split('.')[0] in ROS_MODULES or name.endswith('_msgs')
                          or '_msgs.' in name)
        for path in sorted(CORE.glob('*.py'))
    }
    assert {k: v for k, v in offending.items() if v} == {}


@pytest.mark.parametrize('path', runtime_modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_runtime_code_never_imports_the_test_scaffolding(path: Path) -> None:
    scaffolding = sorted(name for name in imports(path) if is_scaffolding(name))
    assert scaffolding == [], f'{path.relative_to(SRC)} imports {scaffolding}'


def test_the_runtime_check_sees_the_drivers_and_their_tool_code() -> None:
    """The rule above is not vacuous: it covers every driver's package, and the tool code
    the registry names sits in the ``testing`` packages it leaves out."""
    covered = {path.relative_to(SRC).parts[0] for path in runtime_modules()}
    assert covered == set(packages())
    assert is_scaffolding('capture_driver.testing.sim_handle')
    assert not is_scaffolding('capture_driver.client')
    tool_code = [path for package in packages()
                 for path in (SRC / package / package).rglob('*.py')
                 if path.name in ('sim_handle.py', 'demo_steps.py')]
    assert tool_code
    assert all(path.parent.name == 'testing' for path in tool_code)


#: what ARCHITECTURE.md cites from other projects (python-can's test suite)
EXTERNAL_FILES = ('back2back_test.py',)
PLACEHOLDER = re.compile(r'<(pkg|driver|device)>')
SKIPPED_PARTS = {'.venv', 'build', 'install', 'log', '.git', 'bench_output'}


def architecture_citations() -> tuple[list[str], list[str]]:
    """(file paths, dotted names) in ARCHITECTURE.md's backquotes."""
    text = (ROOT / 'ARCHITECTURE.md').read_text(encoding='utf-8')
    files = re.findall(r'`([^`\s]+\.(?:py|md|yaml|xacro|xml|cfg|sh))(?:::\w+)?`', text)
    names = re.findall(r'`([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)(?:\(\))?`', text)
    return sorted(set(files)), sorted({n for n in names if n not in files
                                       and not n.endswith(('.py', '.md', '.cfg'))})


def test_every_file_architecture_names_exists() -> None:
    repository = [p.relative_to(ROOT) for p in ROOT.rglob('*')
                  if p.is_file() and not SKIPPED_PARTS & set(p.relative_to(ROOT).parts)]
    files, _ = architecture_citations()
    missing = [cited for cited in files if cited not in EXTERNAL_FILES
               and not any(path.match(PLACEHOLDER.sub('*', cited)) for path in repository)]
    assert missing == []


def test_every_name_architecture_cites_is_defined() -> None:
    """``controller.yield_core``, ``Device.post_move``: the last part is defined (def,
    class or assignment) in the code, or the whole is a module or package of it."""
    code = '\n'.join(p.read_text(encoding='utf-8') for p in SRC.rglob('*.py')
                     if not SKIPPED_PARTS & set(p.parts))
    _, names = architecture_citations()
    assert names, 'no citations found: the pattern is wrong'

    def defined(dotted: str) -> bool:
        module = SRC / dotted.split('.')[0] / dotted.replace('.', '/')
        last = re.escape(dotted.rsplit('.', 1)[1])
        return (module.with_suffix('.py').is_file() or module.is_dir() or bool(re.search(
            rf'^\s*(?:async\s+)?(?:def|class)\s+{last}\b|^\s*(?:self\.)?{last}\s*[:=]',
            code, re.M)))

    assert [name for name in names if not defined(name)] == []
