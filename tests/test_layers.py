"""The layers of ARCHITECTURE.md, read from the imports of the code (ast).

- the core's top-level modules are ROS-free (the package docstring says so);
- runtime code never imports the test scaffolding (``gimbal_driver_common.testing``): only
  tests, the tools (``scripts/``, ``bench/``) and the tool code a driver registers for them
  (``<driver>/sim_handle.py`` for the soak, bench and tests; ``<driver>/demo_steps.py`` for
  the demo) do.
"""

from __future__ import annotations

import ast
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
