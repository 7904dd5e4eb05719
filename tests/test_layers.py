"""The layers of ARCHITECTURE.md, read from the imports of the code (ast).

- the core's top-level modules are ROS-free (the package docstring says so);
- runtime code never imports the test support (the package ``gimbal_driver_testing``) nor
  a test library (pytest, hypothesis, geographiclib): every module of every other package
  is runtime, with no exemption, a driver's simulator handle, demo steps and refused-request
  data included (the registry names them, tools import them);
- ARCHITECTURE.md names only what exists: every file it names (``<pkg>`` and the like
  stand for each driver), and every name it cites is defined where the citation points:
  ``file.py`` ``Name`` in that file (for ``<pkg>/...``, in every driver's), ``module.name``
  in that module, ``Class.member`` in that class or its bases, another library's name in
  that library. A name defined somewhere else does not count.
"""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / 'src'
CORE = SRC / 'gimbal_driver_common' / 'gimbal_driver_common'
#: top-level modules of ROS client libraries and message packages
ROS_MODULES = ('rclpy', 'launch', 'launch_ros', 'ament_index_python')
#: the one package of test support (conformance suites, harness, ROS test client)
TEST_SUPPORT = 'gimbal_driver_testing'
#: libraries only tests use (docs/development.md, "rosdep keys")
TEST_LIBRARIES = ('pytest', 'hypothesis', 'geographiclib')


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
    """Every installed Python module of every package but the test support."""
    modules = []
    for package in packages():
        if package != TEST_SUPPORT:
            modules.extend(sorted((SRC / package / package).rglob('*.py')))
    return modules


def is_scaffolding(name: str) -> bool:
    """Whether a dotted import names the test support or a test library (or a module of
    one)."""
    return name.split('.')[0] in (TEST_SUPPORT, *TEST_LIBRARIES)


def test_the_core_top_level_is_ros_free() -> None:
    offending = {
        path.name: sorted(name for name in imports(path)
                          if name.split('.')[0] in ROS_MODULES or name.endswith('_msgs')
                          or '_msgs.' in name)
        for path in sorted(CORE.glob('*.py'))
    }
    assert {k: v for k, v in offending.items() if v} == {}


@pytest.mark.parametrize('path', runtime_modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_runtime_code_never_imports_the_test_support(path: Path) -> None:
    scaffolding = sorted(name for name in imports(path) if is_scaffolding(name))
    assert scaffolding == [], f'{path.relative_to(SRC)} imports {scaffolding}'


def test_the_runtime_check_sees_the_drivers_and_their_tool_code() -> None:
    """The rule above is not vacuous: it covers every package but the test support, and the
    tool code the registry names (simulator handles, demo steps, refused-request data) is
    among the modules it checks."""
    covered = {path.relative_to(SRC).parts[0] for path in runtime_modules()}
    assert covered == set(packages()) - {TEST_SUPPORT}
    assert TEST_SUPPORT in packages()
    assert is_scaffolding('gimbal_driver_testing.conformance')
    assert is_scaffolding('hypothesis.strategies')
    assert not is_scaffolding('capture_driver.sim_handle')
    assert not is_scaffolding('gimbal_driver_common.sim_handle')
    runtime = set(runtime_modules())
    tool_code = [path for package in packages()
                 for path in (SRC / package / package).rglob('*.py')
                 if path.name in ('sim_handle.py', 'demo_steps.py', 'refused_requests.py')
                 and package != TEST_SUPPORT]
    assert len(tool_code) >= 10
    assert set(tool_code) <= runtime


#: what ARCHITECTURE.md cites from other projects (python-can's test suite)
EXTERNAL_FILES = ('back2back_test.py',)
PLACEHOLDER = re.compile(r'<(pkg|driver|device)>')
SKIPPED_PARTS = {'.venv', 'build', 'install', 'log', '.git', 'bench_output'}


def architecture_citations(text: str | None = None) -> tuple[list[str], list[str]]:
    """(file paths, dotted names) in ARCHITECTURE.md's backquotes (or in ``text``)."""
    if text is None:
        text = (ROOT / 'ARCHITECTURE.md').read_text(encoding='utf-8')
    files = re.findall(r'`([^`\s]+\.(?:py|md|yaml|xacro|xml|cfg|sh))(?:::\w+)?`', text)
    # ``module.name``, ``Class.member``, ``ros/messages.with_axis_parts``, ``Device.attach(config)``
    names = re.findall(r'`((?:\w+/)*[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)(?:\([^`]*\))?`', text)
    return sorted(set(files)), sorted({n for n in names if n not in files
                                       and not n.endswith(('.py', '.md', '.cfg'))})


def test_every_file_architecture_names_exists() -> None:
    repository = [p.relative_to(ROOT) for p in ROOT.rglob('*')
                  if p.is_file() and not SKIPPED_PARTS & set(p.relative_to(ROOT).parts)]
    files, _ = architecture_citations()
    missing = [cited for cited in files if cited not in EXTERNAL_FILES
               and not any(path.match(PLACEHOLDER.sub('*', cited)) for path in repository)]
    assert missing == []


class Definitions:
    """What each Python file under ``src/`` defines, read with ``ast``: its module-level
    names (def, class, assignment) and, per class, the names its body defines, the
    ``self.<name>`` it assigns in its methods, and its bases. An imported name is not
    defined by the file that imports it."""

    def __init__(self, root: Path = SRC) -> None:
        self.files: dict[Path, tuple[set[str], dict[str, tuple[set[str], list[str]]]]] = {}
        for path in sorted(root.rglob('*.py')):
            if not SKIPPED_PARTS & set(path.parts):
                self.files[path] = self.read(path.read_text(encoding='utf-8'))

    @staticmethod
    def targets(node: ast.AST) -> set[str]:
        """Names an assignment statement binds (``x = ``, ``x: T = ``, ``a, b = ``)."""
        found: set[str] = set()
        nodes = node.targets if isinstance(node, ast.Assign) else [node.target]
        for target in nodes:
            found.update(n.id for n in ast.walk(target) if isinstance(n, ast.Name))
        return found

    @classmethod
    def read(cls, text: str) -> tuple[set[str], dict[str, tuple[set[str], list[str]]]]:
        tree = ast.parse(text)
        module: set[str] = set()
        classes: dict[str, tuple[set[str], list[str]]] = {}
        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                module.add(node.name)
            elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                module.update(cls.targets(node))
        for node in ast.walk(tree):
            if not isinstance(node, ast.ClassDef):
                continue
            members: set[str] = set()
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    members.add(item.name)
                elif isinstance(item, (ast.Assign, ast.AnnAssign)):
                    members.update(cls.targets(item))
            for item in ast.walk(node):  # self.<name> = ... in its methods
                if isinstance(item, (ast.Assign, ast.AnnAssign)):
                    for target in (item.targets if isinstance(item, ast.Assign)
                                   else [item.target]):
                        if (isinstance(target, ast.Attribute)
                                and isinstance(target.value, ast.Name)
                                and target.value.id == 'self'):
                            members.add(target.attr)
            bases = [base.id if isinstance(base, ast.Name) else base.attr
                     for base in node.bases if isinstance(base, (ast.Name, ast.Attribute))]
            classes[node.name] = (members, bases)
        return module, classes

    def in_file(self, path: Path, dotted: str) -> bool:
        """``Name`` defined in this file, at module level or as an attribute of one of its
        classes (``controller.motion_watch``: the controller's), or ``Class.member`` (a
        member also through the class's bases, wherever they are defined)."""
        module, classes = self.files[path]
        first, _, rest = dotted.partition('.')
        if not rest:
            return first in module or any(first in members for members, _ in classes.values())
        return first in classes and self.member(first, rest.split('.')[0], {path})

    def member(self, class_name: str, name: str, preferred: set[Path],
               seen: set[str] | None = None) -> bool:
        """Whether the class (looked up in ``preferred`` first, else anywhere) or one of
        its bases defines ``name``."""
        seen = set() if seen is None else seen
        if class_name in seen:
            return False
        seen.add(class_name)
        owners = [p for p in preferred if class_name in self.files[p][1]] or [
            p for p, (_, classes) in self.files.items() if class_name in classes]
        for path in owners:
            members, bases = self.files[path][1][class_name]
            if name in members or any(self.member(base, name, {path}, seen)
                                      for base in bases):
                return True
        return False

    def modules(self, dotted_path: str) -> list[Path]:
        """Files that are the module (``a/b.py``) or package (``a/b/__init__.py``) a dotted
        or slashed path names."""
        tail = dotted_path.replace('.', '/')
        return [p for p in self.files
                if p.as_posix().endswith((f'/{tail}.py', f'/{tail}/__init__.py'))]

    def cited(self, dotted: str) -> bool:
        """A dotted citation resolves: the longest module prefix that names a module of
        ours must define the rest; with no module prefix, the first part is a class whose
        body (or bases) defines the second."""
        parts = dotted.split('.')
        for split in range(len(parts), 0, -1):
            files = self.modules('.'.join(parts[:split]))
            if files:
                rest = '.'.join(parts[split:])
                return not rest or any(self.in_file(path, rest) for path in files)
        if len(parts) >= 2 and any(parts[0] in classes for _, classes in self.files.values()):
            return self.member(parts[0], parts[1], set())
        return len(parts) >= 2 and external(dotted)


def external(dotted: str) -> bool:
    """A name of another library (``logging.Handler``): its module imports and has it."""
    parts = dotted.split('.')
    for split in range(len(parts) - 1, 0, -1):
        try:
            value: object = importlib.import_module('.'.join(parts[:split]))
        except ImportError:
            continue
        for part in parts[split:]:
            if not hasattr(value, part):
                return False
            value = getattr(value, part)
        return True
    return False


#: ``file`` ``Name`` (or ``file``: ``Name``) next to each other, and ``file::test_name``
PAIR = re.compile(r'`([^`\s]+\.py)`:?\s+`([A-Za-z_][\w.]*)(?:\(\))?`')
TEST_ID = re.compile(r'`([^`\s]+\.py)::(\w+)`')


def file_citations(text: str) -> list[tuple[str, str]]:
    """(file, name) pairs: a name cited right after the file it is in."""
    return sorted(set(PAIR.findall(text)) | set(TEST_ID.findall(text)))


def cited_files(definitions: Definitions, cited: str) -> list[Path]:
    """The files a cited path means (``<pkg>`` and the like: every driver's)."""
    pattern = PLACEHOLDER.sub('*', cited)
    return [path for path in definitions.files if path.match(pattern)]


def citation_errors(text: str, definitions: Definitions) -> list[str]:
    """Every citation of ARCHITECTURE.md's kind in ``text`` that the code does not hold."""
    errors = []
    for cited, name in file_citations(text):
        files = cited_files(definitions, cited)
        if not files:
            if cited not in EXTERNAL_FILES:
                errors.append(f'`{cited}`: no such file')
            continue
        defining = [path for path in files if definitions.in_file(path, name)]
        # a placeholder path is a claim about every driver; a bare file name about one file
        if not defining or (PLACEHOLDER.search(cited) and len(defining) < len(files)):
            missing = sorted(str(p.relative_to(SRC)) for p in files if p not in defining)
            errors.append(f'`{cited}` `{name}`: not defined in {missing}')
    _, names = architecture_citations(text)
    errors += [f'`{name}`: not defined where it points' for name in names
               if not definitions.cited(name)]
    return errors


@pytest.fixture(scope='module')
def definitions() -> Definitions:
    return Definitions()


def test_every_name_architecture_cites_is_defined_where_it_says(definitions) -> None:
    """``ros/run.py`` ``InlineGroupExecutor``: defined in that file; ``controller.yield_core``,
    ``Device.post_move``: defined in that module, or in that class (or its bases)."""
    text = (ROOT / 'ARCHITECTURE.md').read_text(encoding='utf-8')
    assert file_citations(text) and architecture_citations(text)[1], 'the patterns are wrong'
    assert citation_errors(text, definitions) == []


def test_a_wrong_citation_fails(definitions) -> None:
    """Each kind of citation, cited where its name is not, is caught (the old check passed
    any name defined anywhere)."""
    wrong = ('`ros/run.py` `GimbalController`, `gimbal_driver_common/session.py`: `LinkLock`, '
             '`<pkg>/device.py` `CaptureDevice`, `controller.InlineGroupExecutor`, '
             '`Device.record_targets`, `test_controller.py::test_that_does_not_exist`, '
             '`ros/run.py` `InlineGroupExecutor.no_such_method`, `logging.NoSuchHandler`, '
             '`ros/messages.with_axis_part`')
    assert citation_errors(wrong, definitions) == [
        '`<pkg>/device.py` `CaptureDevice`: not defined in '
        + str(sorted(str(p.relative_to(SRC)) for p in cited_files(definitions, '<pkg>/device.py')
                     if 'capture_driver' not in p.parts)),
        '`gimbal_driver_common/session.py` `LinkLock`: not defined in '
        "['gimbal_driver_common/gimbal_driver_common/session.py']",
        '`ros/run.py` `GimbalController`: not defined in '
        "['gimbal_driver_common/gimbal_driver_common/ros/run.py']",
        '`ros/run.py` `InlineGroupExecutor.no_such_method`: not defined in '
        "['gimbal_driver_common/gimbal_driver_common/ros/run.py']",
        '`test_controller.py` `test_that_does_not_exist`: not defined in '
        "['gimbal_driver_common/test/test_controller.py']",
        '`Device.record_targets`: not defined where it points',
        '`InlineGroupExecutor.no_such_method`: not defined where it points',
        '`controller.InlineGroupExecutor`: not defined where it points',
        '`logging.NoSuchHandler`: not defined where it points',
        '`ros/messages.with_axis_part`: not defined where it points',
    ]
    right = ('`ros/run.py` `InlineGroupExecutor`, `controller.periodic`, `Device.post`, '
             '`logging.Handler`, `gimbal_driver_common.session.Session`, '
             '`ros/messages.with_axis_parts`, `Device.attach(config, log)`, '
             '`test_controller.py::test_a_blocked_sensor_read_does_not_delay_the_dead_man_stop`')
    assert citation_errors(right, definitions) == []
