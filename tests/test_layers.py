"""The layers of ARCHITECTURE.md, read from the imports of the code (ast).

- the core's top-level modules are ROS-free (the package docstring says so);
- runtime code never imports the test scaffolding (``gimbal_driver_common.testing``): only
  tests, the tools (``scripts/``, ``bench/``) and the tool code a driver registers for them
  (``<driver>/sim_handle.py`` for the soak, bench and tests; ``<driver>/demo_steps.py`` for
  the demo) do;
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
#: driver modules that only the tools load (through the registry's module:attribute names)
TOOL_MODULES = ('sim_handle.py', 'demo_steps.py')


def imports(path: Path) -> set[str]:
    """Dotted names of the absolute imports of one file (``from a.b import c`` gives a.b
    and a.b.c, so a check on a package also sees what is imported from it)."""
    tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module)
            found.update(f'{node.module}.{alias.name}' for alias in node.names)
    return found


def runtime_modules() -> list[Path]:
    """Every installed Python module of every package, except test helpers and the tool
    code the registry names (simulator handles, demo steps)."""
    modules = []
    for package in sorted(p.parent for p in SRC.glob('*/setup.py')):
        for path in sorted((package / package.name).rglob('*.py')):
            relative = path.relative_to(package / package.name)
            if 'testing' in relative.parts or path.name in TOOL_MODULES:
                continue
            modules.append(path)
    return modules


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
    scaffolding = sorted(name for name in imports(path)
                         if name == 'gimbal_driver_common.testing'
                         or name.startswith('gimbal_driver_common.testing.'))
    assert scaffolding == [], f'{path.relative_to(SRC)} imports {scaffolding}'


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
