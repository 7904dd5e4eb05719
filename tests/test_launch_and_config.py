"""Every driver's launch files and parameter YAML files are valid and name only
parameters that the node declares.

There is no ``launch``/``launch_ros`` on PyPI, so the launch files are executed
against small recording stand-ins for those modules: enough to run
``generate_launch_description()`` and collect every Node's package,
executable, name and parameters. Each YAML file is then loaded by the real
node (a process with ``autostart:=false``, so nothing is connected) and the
node's declared parameters (``list_parameters``) must cover every key.
"""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path

import pytest
import yaml
from rcl_interfaces.srv import ListParameters

from gimbal_driver_common.registry import REFERENCE_PACKAGE, drivers
from gimbal_driver_common.testing import DomainLease, ManagedProcess, find_executable
from gimbal_driver_common.testing.ros import RosTestClient

pytestmark = pytest.mark.ros

SRC = Path(__file__).resolve().parent.parent / 'src'
#: package -> node executable of every registered driver (the reference virtual gimbal too)
DRIVERS = {spec.package: spec.node_executable for spec in drivers()}


class Recorded:
    """Stand-in for any launch action or substitution: remembers its arguments."""

    instances: list[Recorded] = []

    def __init__(self, *args: object, **kwargs: object) -> None:
        self.args, self.kwargs = args, kwargs
        Recorded.instances.append(self)

    def __truediv__(self, other: object) -> Recorded:
        return Recorded(self, other)


LAUNCH_DEFAULTS: dict[str, str] = {}


class DeclareLaunchArgument(Recorded):
    def __init__(self, name: str, *args: object, **kwargs: object) -> None:
        super().__init__(name, *args, **kwargs)
        LAUNCH_DEFAULTS[name] = str(kwargs.get('default_value', ''))


class LaunchConfiguration(Recorded):
    """Evaluates to the launch argument's default, as `ros2 launch` without arguments."""

    def perform(self, context: object) -> str:
        return LAUNCH_DEFAULTS.get(str(self.args[0]), '')


SPECIAL = {'DeclareLaunchArgument': DeclareLaunchArgument,
           'LaunchConfiguration': LaunchConfiguration}


def _module(name: str) -> types.ModuleType:
    module = types.ModuleType(name)

    def factory(attr: str) -> type:
        if attr.startswith('__'):
            raise AttributeError(attr)
        return SPECIAL.get(attr) or type(attr, (Recorded,), {})

    module.__getattr__ = factory  # type: ignore[attr-defined]
    module.__path__ = []  # a package, so submodules import
    return module


@pytest.fixture
def launch_stubs(monkeypatch):
    for name in ('launch', 'launch.actions', 'launch.substitutions', 'launch.conditions',
                 'launch.event_handlers', 'launch.events', 'launch_ros', 'launch_ros.actions',
                 'launch_ros.substitutions', 'launch_ros.events', 'launch_ros.event_handlers',
                 'launch_ros.events.lifecycle', 'launch.launch_description_sources'):
        monkeypatch.setitem(sys.modules, name, _module(name))
    Recorded.instances = []
    LAUNCH_DEFAULTS.clear()
    yield


def run_launch_file(path: Path, arguments: dict[str, str] | None = None) -> list[Recorded]:
    """Run a launch file as `ros2 launch` would with ``arguments`` (name:=value)."""
    spec = importlib.util.spec_from_file_location(f'launch_under_test_{path.stem}', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.generate_launch_description()
    LAUNCH_DEFAULTS.update(arguments or {})
    for action in list(Recorded.instances):
        if type(action).__name__ == 'OpaqueFunction':
            action.kwargs['function'](object(), *action.kwargs.get('args', ()))
    return [r for r in Recorded.instances
            if type(r).__name__ in ('Node', 'LifecycleNode') and 'executable' in r.kwargs]


def launch_files() -> list[tuple[str, Path]]:
    return [(pkg, path) for pkg in DRIVERS for path in sorted((SRC / pkg / 'launch').glob('*.py'))]


def config_files() -> list[tuple[str, Path]]:
    return [(pkg, path) for pkg in DRIVERS
            for path in sorted((SRC / pkg / 'config').glob('*.yaml'))]


def test_every_driver_ships_launch_and_configs() -> None:
    for pkg in DRIVERS:
        assert list((SRC / pkg / 'launch').glob('*.launch.py')), f'{pkg} has no launch file'
        configs = [p.name for p in (SRC / pkg / 'config').glob('*.yaml')]
        assert f'{pkg}.yaml' in configs, f'{pkg}: no real-hardware YAML'
        if pkg != REFERENCE_PACKAGE:  # the reference's device is its simulator
            assert any('sim' in c for c in configs), f'{pkg}: no simulator YAML'


@pytest.mark.parametrize(('pkg', 'path'), launch_files(), ids=lambda v: getattr(v, 'name', v))
def test_launch_file_runs_and_starts_the_driver(launch_stubs, pkg: str, path: Path) -> None:
    nodes = run_launch_file(path)
    assert nodes, f'{path.name} starts no node'
    assert any(n.kwargs['executable'] == DRIVERS[pkg] for n in nodes)
    for node in nodes:
        assert node.kwargs.get('package') == pkg
        find_executable(pkg, node.kwargs['executable'])  # the executable is installed
        if node.kwargs['executable'] != DRIVERS[pkg]:
            continue
        for entry in node.kwargs.get('parameters', []):
            if isinstance(entry, dict):
                unknown = set(entry) - declared_parameters(pkg)
                assert not unknown, f'{path.name} sets undeclared parameters {unknown}'


@pytest.mark.parametrize('pkg', list(DRIVERS))
def test_use_description_starts_robot_state_publisher_with_the_urdf(launch_stubs, pkg: str) -> None:
    from gimbal_driver_common.kinematics import AimingChain

    path = SRC / pkg / 'launch' / f'{pkg}.launch.py'
    by_default = run_launch_file(path)
    assert not [n for n in by_default if n.kwargs['executable'] == 'robot_state_publisher']
    Recorded.instances = []
    LAUNCH_DEFAULTS.clear()
    nodes = run_launch_file(path, {'use_description': 'true'})
    publishers = [n for n in nodes if n.kwargs['executable'] == 'robot_state_publisher']
    assert len(publishers) == 1, f'{path.name} with use_description:=true'
    assert publishers[0].kwargs['package'] == 'robot_state_publisher'
    description = publishers[0].kwargs['parameters'][0]['robot_description']
    chain = AimingChain.from_xml(description)  # the installed URDF of this package
    assert chain.base_frame == 'base_link'
    driver = next(n for n in nodes if n.kwargs['executable'] == DRIVERS[pkg])
    given = [p for p in driver.kwargs['parameters'] if isinstance(p, dict)]
    # the node aims ~/look_at with the same file robot_state_publisher publishes
    sources = [p['description_file'] for p in given if 'description_file' in p]
    assert len(sources) == 1
    assert sources[0].perform(None) == LAUNCH_DEFAULTS['description_file']
    assert LAUNCH_DEFAULTS['description_file'].endswith(f'share/{pkg}/urdf/{pkg}.urdf')


@pytest.mark.parametrize(('pkg', 'path'), config_files(), ids=lambda v: getattr(v, 'name', v))
def test_config_sets_only_declared_parameters(pkg: str, path: Path) -> None:
    data = yaml.safe_load(path.read_text())
    assert isinstance(data, dict) and data, f'{path.name} is empty'
    for section, content in data.items():
        assert section in (pkg, '/**', f'/{pkg}', '**'), f'{path.name}: section {section!r}'
        params = content['ros__parameters']
        unknown = set(params) - declared_parameters(pkg)
        assert not unknown, f'{path.name} sets parameters the node does not declare: {unknown}'


_DECLARED: dict[str, set[str]] = {}


def declared_parameters(pkg: str) -> set[str]:
    """Parameter names the node declares (asked from a running, unconfigured node)."""
    if pkg in _DECLARED:
        return _DECLARED[pkg]
    with DomainLease() as domain:
        node = ManagedProcess.ros(pkg, DRIVERS[pkg], domain,
                                  ['--ros-args', '-p', 'autostart:=false'])
        try:
            with RosTestClient(domain, 'launch_check') as ros:
                reply = ros.call(ListParameters, f'/{pkg}/list_parameters',
                                 ListParameters.Request(), timeout=30)
        finally:
            node.stop()
    names = set(reply.result.names)
    assert 'publish_rate' in names, f'{pkg}: common parameters missing: {sorted(names)}'
    _DECLARED[pkg] = names
    return names
