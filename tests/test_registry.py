"""The driver registry finds every driver through the installed entry points, and every
spec's executables and references are real (gimbal_driver_common.registry).

The registry is what the demo, the soak, the benchmarks and these tests iterate over, so a
spec that names a missing executable, simulator handle, demo step or benchmark would only
show up as a failure deep inside one of those runs; here it fails by name.
"""

from __future__ import annotations

import inspect
from importlib.metadata import entry_points
from pathlib import Path

import pytest

from gimbal_driver_common import registry
from gimbal_driver_common.registry import (
    ENTRY_POINT_GROUP,
    DriverSpec,
    RegistryError,
    drivers,
    parameter_arguments,
    resolve,
)
from gimbal_driver_common.sim_handle import SimHandle

ROOT = Path(__file__).resolve().parent.parent
INSTALL = ROOT / 'install'

pytestmark = pytest.mark.skipif(not (INSTALL / 'setup.bash').exists(),
                                reason='the workspace is not built (make build)')


def test_every_driver_registers_through_its_installed_entry_point() -> None:
    """Each spec the registry finds comes from its colcon-installed package's entry point
    (``<package>.registration:SPEC``); which packages must be there is the next test's."""
    specs = drivers()
    assert specs and specs[0].name == 'virtual_gimbal'  # the reference first
    entries = {entry.name: entry for entry in entry_points(group=ENTRY_POINT_GROUP)}
    for spec in specs:
        entry = entries[spec.name]
        # the registration comes from the colcon-installed package, not the source tree
        location = Path(entry.dist.locate_file('')).resolve()
        assert location.is_relative_to(INSTALL / spec.package), (spec.name, location)
        assert entry.value == f'{spec.package}.registration:SPEC'


def test_every_package_in_src_with_a_node_is_registered() -> None:
    """A driver package that forgot its entry point would silently drop out of the demo,
    soak, bench and tests: every src/ package that installs a ``*_node`` must register."""
    registered = {spec.package for spec in drivers()}
    for setup in sorted((ROOT / 'src').glob('*/setup.py')):
        if '_node = ' in setup.read_text(encoding='utf-8'):
            assert setup.parent.name in registered, f'{setup.parent.name} is not registered'
            assert ENTRY_POINT_GROUP in setup.read_text(encoding='utf-8')


@pytest.mark.parametrize('spec', drivers(), ids=lambda spec: spec.name)
def test_executables_exist_in_install(spec: DriverSpec) -> None:
    for executable in spec.executables():
        path = INSTALL / spec.package / 'lib' / spec.package / executable
        assert path.is_file(), f'{spec.name}: {path} is not installed'
        assert path.stat().st_mode & 0o111, f'{spec.name}: {path} is not executable'


@pytest.mark.parametrize('spec', drivers(), ids=lambda spec: spec.name)
def test_references_load(spec: DriverSpec) -> None:
    """The node class, the simulator handle, the probe, the demo steps and the benchmark
    exist, and the node's joints are the spec's (in some order: the spec may reorder them)."""
    node = resolve(spec.node_class)
    assert sorted(node.DEFAULT_JOINT_NAMES) == sorted(spec.joints)
    assert len(spec.move_goal) <= len(spec.joints)
    assert (INSTALL / spec.package / 'share' / spec.package / 'urdf' / spec.description).is_file()
    assert issubclass(resolve(spec.sim_handle), SimHandle)
    if spec.probe:  # gimbal_probe calls it with a ProbeLink
        assert list(inspect.signature(resolve(spec.probe)).parameters) == ['link']
    if spec.refused_requests:
        from hypothesis.strategies import SearchStrategy

        from gimbal_driver_common.registry import RefusedRequests
        from gimbal_driver_testing.refused_requests import strategy

        refused = resolve(spec.refused_requests)()
        assert isinstance(refused, RefusedRequests)
        assert isinstance(strategy(refused), SearchStrategy)
    for label, reference in spec.demo.extra_steps:
        if reference:
            step = resolve(reference)
            assert list(inspect.signature(step).parameters) == ['target', 'ros'], label
        else:
            assert label == 'home', f'{spec.name}: step {label!r} names no function'
    if spec.demo.scan is not None:
        from gimbal_msgs.srv import StartScan

        StartScan.Request(**spec.demo.scan)  # every field exists
    if spec.bench.module:
        assert (ROOT / 'bench' / f'bench_{spec.bench.module}.py').is_file()
    else:
        assert spec.bench.stream_joint in spec.joints


#: what every simulator handle implements itself (the base raises NotImplementedError)
HANDLE_CONTRACT = ('start', 'controls', 'changing', 'motion', 'moving')


@pytest.mark.parametrize('spec', drivers(), ids=lambda spec: spec.name)
def test_sim_handle_carries_the_receive_side_and_takeover_facts(spec: DriverSpec,
                                                                tmp_path: Path) -> None:
    """The one in-process handle serves the soak, the benchmark, the conformance suite and
    the property/crash-safety tests: it classifies what its device receives, reports
    motion, reaches the simulator's control verbs, and names a far move and a goal on its
    own joints."""
    handle_class = resolve(spec.sim_handle)
    missing = [name for name in HANDLE_CONTRACT
               if getattr(handle_class, name) is getattr(SimHandle, name)]
    assert not missing, f'{handle_class.__name__} does not implement {missing}'
    handle = handle_class(spec, tmp_path, process_tests=True)
    assert handle.far_move[0] in spec.joints
    assert set(handle.takeover_goal) <= set(spec.joints)
    handle.start()
    try:
        assert handle.control('state').startswith('{')
        assert all(not handle.moving(joint) for joint in spec.joints)
        assert handle.requests() == [] and handle.motion_received() == 0
        assert all(':=' in parameter for parameter in handle.link_parameters())
    finally:
        handle.close()


@pytest.mark.parametrize('spec', drivers(), ids=lambda spec: spec.name)
def test_placeholders_fill(spec: DriverSpec, tmp_path: Path) -> None:
    """Every placeholder a spec names exists; a password goes to a 0600 file, never onto the
    command line."""
    arguments = parameter_arguments(spec.parameters(tmp_path, 4321)) + spec.sim_argv(tmp_path,
                                                                                    4321)
    assert not [a for a in arguments if '{' in a and '}' in a and ':=[' not in a], arguments
    node_line = ' '.join(parameter_arguments(spec.parameters(tmp_path, 4321)))
    if 'port' in spec.node_parameters:
        assert spec.parameters(tmp_path, 4321)['port'] == 4321  # an int parameter stays one
    if spec.password:
        assert spec.password not in node_line
        password_file = tmp_path / f'{spec.name}_password'
        assert password_file.read_text(encoding='utf-8').strip() == spec.password
        assert password_file.stat().st_mode & 0o777 == 0o600


def test_parameter_arguments_keep_types() -> None:
    assert parameter_arguments({'rate': 20.0, 'port': 4950, 'on': True, 'names': ['a', 'b'],
                                'scales': [1.0, 2.5], 'ids': [2, 3]}) == [
        '-p', 'rate:=20.0', '-p', 'port:=4950', '-p', 'on:=true', '-p', "names:=['a', 'b']",
        '-p', 'scales:=[1.0, 2.5]', '-p', 'ids:=[2, 3]']


class FakeEntryPoint:
    def __init__(self, name: str, value: object) -> None:
        self.name, self.value, self._value = name, f'fake:{name}', value

    def load(self) -> object:
        if isinstance(self._value, Exception):
            raise self._value
        return self._value


def spec_named(name: str, package: str = 'pkg') -> DriverSpec:
    return DriverSpec(name=name, title=name, package=package, node_executable='n',
                      node_name='n', sim_executable='s', node_class='m:C', description='d',
                      joints=('pan',), move_goal=(0.0,))


@pytest.mark.parametrize(('entries', 'message'), [
    ([FakeEntryPoint('a', ImportError('no module b'))], 'does not load: ImportError'),
    ([FakeEntryPoint('a', object())], 'not a DriverSpec'),
    ([FakeEntryPoint('a', spec_named('b'))], 'must equal spec.name'),
    ([FakeEntryPoint('a', spec_named('a', 'p1')), FakeEntryPoint('a', spec_named('a', 'p2'))],
     "two drivers are registered as 'a'"),
])
def test_bad_registrations_are_named(monkeypatch, entries: list, message: str) -> None:
    monkeypatch.setattr(registry, 'entry_points', lambda group: entries)
    with pytest.raises(RegistryError, match=message):
        registry.drivers()


def test_resolve_names_what_is_missing() -> None:
    with pytest.raises(RegistryError, match='not a module:attribute'):
        resolve('gimbal_driver_common.registry.drivers')
    with pytest.raises(RegistryError, match='does not load'):
        resolve('gimbal_driver_common.registry:no_such_thing')
    assert resolve('gimbal_driver_common.registry:drivers') is drivers
