"""Every driver's launch file and parameter YAML files: the contract's launch arguments, run
as `ros2 launch` runs them, and only parameters that the node declares.

``launch``/``launch_ros`` are not installable here, so the launch files run against
``launch_standin`` (tests/launch_standin.py), which executes the actions in order with
Jazzy's rules: a LaunchConfiguration read before its DeclareLaunchArgument has run fails
as it does under ``ros2 launch`` (the old U-Camera file did), OpaqueFunctions run when
reached, Node parameters are resolved when the node is executed. What the launch would
start is then started for real where it matters (``sim:=true``: the simulator and the
node, from the command lines and parameter files the launch produced). Each YAML file is
loaded by the real node (``autostart:=false``, nothing connected) and the node's declared
parameters (``list_parameters``) must cover every key.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import launch_standin
import pytest
import yaml
from ament_index_python.packages import get_package_share_directory
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import GetState
from rcl_interfaces.srv import ListParameters
from sensor_msgs.msg import JointState

from gimbal_driver_common.registry import (
    DriverSpec,
    drivers,
    parameter_arguments,
)
from gimbal_driver_common.sim_control import parse_ready_line
from gimbal_driver_common.testing import (
    DomainLease,
    ManagedProcess,
    find_executable,
    free_tcp_port,
    ros_env,
    wait_for,
)
from gimbal_driver_common.testing.ros import RosTestClient

pytestmark = pytest.mark.ros

SRC = Path(__file__).resolve().parent.parent / 'src'
#: package -> registry spec of every registered driver (the reference virtual gimbal too)
SPECS: dict[str, DriverSpec] = {spec.package: spec for spec in drivers()}
DRIVERS = {package: spec.node_executable for package, spec in SPECS.items()}
#: docs/interface.md: every driver's launch file takes these arguments (defaults; the URDF's
#: default is the package's installed one). A bare launch ends with an active node.
CONTRACT_ARGUMENTS = {'params_file': '', 'autostart': 'true', 'namespace': '',
                      'use_description': 'false', 'description_file': None, 'sim': 'false'}


@pytest.fixture
def launch(monkeypatch):
    launch_standin.install(monkeypatch)
    return launch_standin


def launch_file(pkg: str) -> Path:
    return SRC / pkg / 'launch' / f'{pkg}.launch.py'


def share(pkg: str, *parts: str) -> Path:
    return Path(get_package_share_directory(pkg), *parts)


def config_files() -> list[tuple[str, Path]]:
    """The node parameter files (not the ros2_control controllers' YAML)."""
    return [(pkg, path) for pkg in DRIVERS
            for path in sorted((SRC / pkg / 'config').glob('*.yaml'))
            if not path.name.endswith('_controllers.yaml')]


def test_every_driver_ships_launch_and_configs() -> None:
    for pkg in DRIVERS:
        assert [p.name for p in (SRC / pkg / 'launch').glob('*.launch.py')] == [
            f'{pkg}.launch.py'], f'{pkg}: one launch file, named after the package'
        configs = [p.name for p in (SRC / pkg / 'config').glob('*.yaml')]
        assert f'{pkg}.yaml' in configs, f'{pkg}: no real-hardware YAML'
        assert f'{pkg}_sim.yaml' in configs, f'{pkg}: no simulator YAML'
        # the ros2_control example (tests/test_ros2_control_examples.py), installed
        for name in (f'{pkg}.ros2_control.xacro', f'{pkg}_controllers.yaml'):
            assert share(pkg, 'config', name).is_file(), f'{pkg}: {name} not installed'


@pytest.mark.parametrize('pkg', list(DRIVERS))
def test_the_launch_file_is_the_one_shared_description(pkg: str) -> None:
    """One line, like every driver's: generate_launch_description returns
    driver_launch_description('<pkg>')."""
    tree = ast.parse(launch_file(pkg).read_text())
    function = next(node for node in tree.body if isinstance(node, ast.FunctionDef)
                    and node.name == 'generate_launch_description')
    body = [node for node in function.body if not isinstance(node, ast.Expr)]
    assert len(body) == 1 and isinstance(body[0], ast.Return), ast.dump(function)
    call = body[0].value
    assert isinstance(call, ast.Call) and call.func.id == 'driver_launch_description'
    assert [arg.value for arg in call.args] == [pkg]


@pytest.mark.parametrize('pkg', list(DRIVERS))
def test_every_launch_file_takes_the_contract_arguments(launch, pkg: str) -> None:
    """What `ros2 launch <pkg> <pkg>.launch.py --show-args` lists."""
    declared = {argument.name: argument.default_value
                for argument in launch.load_description(launch_file(pkg)).declared_arguments()}
    assert set(declared) == set(CONTRACT_ARGUMENTS)
    for name, default in CONTRACT_ARGUMENTS.items():
        if default is not None:
            assert declared[name] == default, name
    assert declared['description_file'] == str(share(pkg, 'urdf', f'{pkg}.urdf'))


@pytest.mark.parametrize('pkg', list(DRIVERS))
def test_launch_file_runs_and_starts_the_driver(launch, pkg: str) -> None:
    spec = SPECS[pkg]
    context = launch.run(launch.load_description(launch_file(pkg)))
    assert not context.warnings, context.warnings
    assert [started.kind for started in context.launched] == ['lifecycle_node']
    node = context.launched[0]
    assert (node.package, node.executable, node.name, node.namespace) == (
        pkg, spec.node_executable, spec.node_name, '')
    assert node.cmd[0] == find_executable(pkg, spec.node_executable)
    params_file, given = node.parameters
    assert params_file == share(pkg, 'config', f'{pkg}.yaml')
    assert given == {'autostart': True,
                     'description_file': str(share(pkg, 'urdf', f'{pkg}.urdf'))}
    unknown = set(given) - declared_parameters(pkg)
    assert not unknown, f'the launch file sets undeclared parameters {unknown}'


@pytest.mark.parametrize('pkg', list(DRIVERS))
def test_launch_arguments_reach_the_node(launch, pkg: str, tmp_path: Path) -> None:
    params = tmp_path / 'robot.yaml'
    params.write_text(yaml.safe_dump({pkg: {'ros__parameters': {'publish_rate': 20.0}}}))
    urdf = tmp_path / 'mine.urdf'
    urdf.write_text(share(pkg, 'urdf', f'{pkg}.urdf').read_text())
    context = launch.run(launch.load_description(launch_file(pkg)), {
        'autostart': 'True', 'namespace': 'robot/gimbal', 'params_file': str(params),
        'description_file': str(urdf)})
    node = context.launched[0]
    assert node.namespace == '/robot/gimbal' and '__ns:=/robot/gimbal' in node.cmd
    assert node.parameters == [params, {'autostart': True, 'description_file': str(urdf)}]
    with pytest.raises(ValueError, match="autostart:='yes'"):
        launch.run(launch.load_description(launch_file(pkg)), {'autostart': 'yes'})


def test_reading_a_launch_configuration_before_its_declaration_fails(launch) -> None:
    """The stand-in is strict where `ros2 launch` is (so the launch tests can fail): a
    configuration read before the action that declares it has run does not exist."""
    def read_it(context: object) -> list[object]:
        return [launch.Node(package='virtual_gimbal_driver',
                            executable='virtual_gimbal_driver_node',
                            parameters=[{'x': launch.LaunchConfiguration('x')}])]

    too_early = launch.LaunchDescription([
        launch.OpaqueFunction(function=read_it),
        launch.DeclareLaunchArgument('x', default_value='1.5')])
    with pytest.raises(launch.SubstitutionFailure,
                       match="launch configuration 'x' does not exist"):
        launch.run(too_early)
    # given on the command line it exists before anything runs (ros2 launch ... x:=2)
    assert launch.run(too_early, {'x': '2'}).launched[0].parameters == [{'x': 2}]
    in_order = launch.LaunchDescription(list(reversed(too_early.entities)))
    assert launch.run(in_order).launched[0].parameters == [{'x': 1.5}]


@pytest.mark.parametrize('pkg', list(DRIVERS))
def test_use_description_starts_robot_state_publisher_with_the_urdf(launch, pkg: str) -> None:
    from gimbal_driver_common.kinematics import AimingChain

    description = launch.load_description(launch_file(pkg))
    context = launch.run(description, {'use_description': 'true', 'namespace': 'cam'})
    driver, publisher = context.launched
    assert (publisher.package, publisher.executable, publisher.namespace) == (
        'robot_state_publisher', 'robot_state_publisher', '/cam')
    xml = publisher.parameters[0]['robot_description']
    assert AimingChain.from_xml(xml).base_frame == 'base_link'  # the package's URDF
    # the node aims ~/look_at with the same file robot_state_publisher publishes
    source = driver.parameters[1]['description_file']
    assert source == str(share(pkg, 'urdf', f'{pkg}.urdf'))
    assert Path(source).read_text() == xml


@pytest.mark.parametrize('autostart', [None, 'false'], ids=['bare', 'autostart_false'])
@pytest.mark.parametrize('pkg', list(DRIVERS))
def test_sim_true_starts_the_simulator_and_the_node_connects_to_it(
        launch, pkg: str, autostart: str | None, tmp_path: Path) -> None:
    """``sim:=true``: the simulator (not a ROS node: no --ros-args) and the node with the
    simulator YAML, whose link address is the one the simulator serves. Both are then
    started from the command lines the launch produced; only the fixed address (TCP port or
    pty path) is swapped for a private one, in both, so runs side by side do not meet.

    A bare launch (no ``autostart`` argument) ends with an active node publishing
    joint_states; ``autostart:=false`` leaves it unconfigured, and a lifecycle manager's
    configure and activate then bring it up."""
    spec = SPECS[pkg]
    arguments = {'sim': 'true'} if autostart is None else {'sim': 'true',
                                                           'autostart': autostart}
    context = launch.run(launch.load_description(launch_file(pkg)), arguments)
    simulator, node = context.launched
    assert simulator.kind == 'process' and '--ros-args' not in simulator.cmd
    assert simulator.cmd == [find_executable(pkg, spec.sim_executable),
                             *spec.launch_sim_arguments]
    sim_yaml = share(pkg, 'config', f'{pkg}_sim.yaml')
    assert node.parameters[0] == sim_yaml
    assert node.parameters[1]['autostart'] is (autostart is None)
    option = next(o for o in ('--port', '--link') if o in simulator.cmd)
    address = simulator.cmd[simulator.cmd.index(option) + 1]
    parameters = yaml.safe_load(sim_yaml.read_text())[spec.node_name]['ros__parameters']
    keys = [k for k, v in parameters.items() if str(v) == address]
    assert keys, f'{sim_yaml.name} must name the simulator address {address}'
    private = free_tcp_port() if option == '--port' else str(tmp_path / 'link')
    sim_cmd = [str(private) if part == address else part for part in simulator.cmd]
    with DomainLease() as domain:
        sim = ManagedProcess(sim_cmd, ros_env(domain), name=spec.sim_executable)
        started = None
        try:
            wait_for(lambda: parse_ready_line(sim.output()) or not sim.running, 30.0,
                     f'{spec.sim_executable} to be ready')
            assert sim.running, sim.output()[-2000:]
            overrides = {**node.parameters[1], **dict.fromkeys(keys, private)}
            node_cmd = [*node.cmd, '--params-file', str(sim_yaml),
                        *parameter_arguments(overrides)]
            started = ManagedProcess(node_cmd, ros_env(domain), name=spec.node_executable)
            with RosTestClient(domain, 'launch_sim_check') as ros:
                if autostart is None:
                    ros.wait_for_lifecycle_state(spec.node_name, 'active', timeout=60)
                else:
                    # once it answers, it is unconfigured, and stays so until told
                    state = ros.call(GetState, f'/{spec.node_name}/get_state',
                                     GetState.Request(), timeout=60, idempotent=True)
                    assert state.current_state.label == 'unconfigured'
                    assert ros.lifecycle_transition(
                        spec.node_name, Transition.TRANSITION_CONFIGURE, timeout=30)
                    assert ros.lifecycle_transition(
                        spec.node_name, Transition.TRANSITION_ACTIVATE, timeout=30)
                msg = ros.wait_for_message('joint_states', JointState, timeout=60)
                assert ros.lifecycle_state(spec.node_name) == 'active'
            assert list(msg.name) == list(parameters.get('joint_names', spec.joints))
            assert all(math.isfinite(p) for p in msg.position)
        finally:
            if started is not None:
                started.stop()
            sim.stop()


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
                                 ListParameters.Request(), timeout=30, idempotent=True)
        finally:
            node.stop()
    names = set(reply.result.names)
    assert 'publish_rate' in names, f'{pkg}: common parameters missing: {sorted(names)}'
    _DECLARED[pkg] = names
    return names
