"""The checks of what a driver package ships for ``ros2 launch``: its launch file and its
parameter YAML files, run by each driver package's own ``test/test_package_files.py``
(a subclass of :class:`LaunchAndConfigSuite` naming the package), so ``colcon test
--packages-select <pkg>`` checks the files that package installs and nothing else.

``launch``/``launch_ros`` are not installable here, so the launch file runs against
:mod:`gimbal_driver_testing.launch_standin`, which executes the actions in order
with Jazzy's rules and builds the node's command line as launch_ros does. What the launch
would start is then started for real where it matters: the node from that command line
(rclpy itself applies the parameter files), and with ``sim:=true`` the simulator too.

Every file is read from the package's installed share directory (ament_index), what
``ros2 launch`` reads. A node under test never dials the factory address the hardware YAML
names (a private network address): it is started with ``autostart:=false`` and left
unconfigured, which the tests check (lifecycle state, and no TCP socket, serial or HID
device open in the process), or given loopback addresses.
"""

from __future__ import annotations

import ast
import math
import os
import re
from pathlib import Path
from typing import Any, ClassVar

import pytest
import yaml

#: docs/interface.md: every driver's launch file takes these arguments (defaults; the URDF's
#: default is the package's installed one). A bare launch ends with an active node.
CONTRACT_ARGUMENTS = {'params_file': '', 'autostart': 'true', 'namespace': '',
                      'use_description': 'false', 'description_file': None, 'sim': 'false',
                      'log_level': ''}
#: a value of each link argument other than any shipped YAML's (as ``ros2 launch`` passes
#: it: text), and the typed value the node then gets
GIVEN_LINK = {'host': ('127.0.0.2', '127.0.0.2'), 'port': ('4321', 4321),
              'transport': ('given-transport', 'given-transport'),
              'serial_port': ('/dev/ttyGIVEN0', '/dev/ttyGIVEN0'),
              'baudrate': ('57600', 57600), 'can_interface': ('virtual', 'virtual'),
              'can_channel': ('given0', 'given0')}
#: what a parameters file of the user's sets them to before the arguments override it
FILE_LINK = {'host': '127.0.0.3', 'port': 1111, 'transport': 'file-transport',
             'serial_port': '/dev/ttyFILE0', 'baudrate': 9600, 'can_interface': 'socketcan',
             'can_channel': 'file0'}
#: the namespace the namespaced launches use (the issue's `namespace:=robot/gimbal`)
NAMESPACE = 'robot/gimbal'

_DECLARED: dict[str, set[str]] = {}


def share(package: str, *parts: str) -> Path:
    """A file of the package's installed share directory (what `ros2 launch` reads)."""
    from ament_index_python.packages import get_package_share_directory

    return Path(get_package_share_directory(package), *parts)


def file_parameters(path: Path) -> dict[str, Any]:
    """The ``ros__parameters`` of a shipped parameter file, which is keyed ``/**`` only."""
    document = yaml.safe_load(path.read_text())
    assert isinstance(document, dict) and document, f'{path.name} is empty'
    assert list(document) == ['/**'], (
        f'{path.name}: keyed {list(document)}; key it /** so it applies under any namespace '
        'and node name (a bare node name reaches only the node in the root namespace)')
    return document['/**']['ros__parameters']


def declared_parameters(package: str) -> set[str]:
    """Parameter names the node declares (asked from a running, unconfigured node)."""
    from rcl_interfaces.srv import ListParameters

    from gimbal_driver_common.registry import driver_of_package
    from gimbal_driver_testing import DomainLease, ManagedProcess
    from gimbal_driver_testing.ros import RosTestClient

    if package in _DECLARED:
        return _DECLARED[package]
    spec = driver_of_package(package)
    with DomainLease() as domain:
        node = ManagedProcess.ros(package, spec.node_executable, domain,
                                  ['--ros-args', '-p', 'autostart:=false'])
        try:
            with RosTestClient(domain, 'launch_check') as ros:
                reply = ros.call(ListParameters, f'/{spec.node_name}/list_parameters',
                                 ListParameters.Request(), timeout=30)
        finally:
            node.stop()
    names = set(reply.result.names)
    assert 'publish_rate' in names, f'{package}: common parameters missing: {sorted(names)}'
    _DECLARED[package] = names
    return names


def same_value(got: Any, want: Any) -> bool:
    """A parameter read back equals the YAML value (numbers within float rounding)."""
    if isinstance(want, (list, tuple)):
        return (isinstance(got, (list, tuple)) and len(got) == len(want)
                and all(same_value(g, w) for g, w in zip(got, want, strict=True)))
    if isinstance(want, float) and isinstance(got, (int, float)):
        return math.isclose(got, want, rel_tol=1e-12, abs_tol=1e-12)
    return type(got) is type(want) and got == want


def open_links(pid: int) -> list[str]:
    """What a process holds that would be a device link: TCP sockets (connecting, connected
    or listening), CAN sockets, and serial, pseudo-terminal or HID devices. DDS' UDP and
    shared memory are not links. From /proc/<pid>/fd and the socket tables of
    /proc/<pid>/net (a TCP socket is listed from its first connect or listen on)."""
    sockets, devices = set(), []
    for fd in Path(f'/proc/{pid}/fd').iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue  # closed meanwhile
        if target.startswith('socket:['):
            sockets.add(target[len('socket:['):-1])
        elif int(fd.name) > 2 and target.startswith(('/dev/tty', '/dev/pts', '/dev/hidraw')):
            devices.append(target)
    held = []
    for table in ('tcp', 'tcp6', 'can/raw', 'can/bcm'):
        path = Path(f'/proc/{pid}/net/{table}')
        if path.is_file():
            for line in path.read_text().splitlines()[1:]:
                held += [f'{table} socket {inode}: {line.split()}'
                         for inode in sorted(sockets & set(line.split()))]
    return held + devices


class LaunchAndConfigSuite:
    """Subclass with ``package = '<pkg>'`` and ``__test__ = True`` in the package's test/."""

    __test__ = False
    package: ClassVar[str] = ''

    @pytest.fixture
    def launch(self, monkeypatch: pytest.MonkeyPatch) -> Any:
        from gimbal_driver_testing import launch_standin

        launch_standin.install(monkeypatch)
        return launch_standin

    @property
    def spec(self) -> Any:
        from gimbal_driver_common.registry import driver_of_package

        return driver_of_package(self.package)

    def launch_file(self) -> Path:
        return share(self.package, 'launch', f'{self.package}.launch.py')

    def run_launch(self, launch: Any, arguments: dict[str, str] | None = None,
                   params_dir: Path | None = None) -> Any:
        return launch.run(launch.load_description(self.launch_file()), arguments, params_dir)

    def test_ships_one_launch_file_and_both_configs(self) -> None:
        pkg = self.package
        assert [p.name for p in share(pkg, 'launch').glob('*.launch.py')] == [
            f'{pkg}.launch.py'], f'{pkg}: one launch file, named after the package'
        configs = {p.name for p in share(pkg, 'config').glob('*.yaml')}
        assert f'{pkg}.yaml' in configs, f'{pkg}: no real-hardware YAML'
        assert f'{pkg}_sim.yaml' in configs, f'{pkg}: no simulator YAML'
        for name in (f'{pkg}.ros2_control.xacro', f'{pkg}_controllers.yaml'):
            assert share(pkg, 'config', name).is_file(), f'{pkg}: {name} not installed'

    def test_the_launch_file_is_the_one_shared_description(self) -> None:
        """One line, like every driver's: generate_launch_description returns
        driver_launch_description('<pkg>')."""
        tree = ast.parse(self.launch_file().read_text())
        function = next(node for node in tree.body if isinstance(node, ast.FunctionDef)
                        and node.name == 'generate_launch_description')
        body = [node for node in function.body if not isinstance(node, ast.Expr)]
        assert len(body) == 1 and isinstance(body[0], ast.Return), ast.dump(function)
        call = body[0].value
        assert isinstance(call, ast.Call) and call.func.id == 'driver_launch_description'
        assert [arg.value for arg in call.args] == [self.package]

    def test_the_launch_file_takes_the_contract_arguments(self, launch: Any) -> None:
        """What `ros2 launch <pkg> <pkg>.launch.py --show-args` lists."""
        declared = {argument.name: argument.default_value for argument in
                    launch.load_description(self.launch_file()).declared_arguments()}
        links = dict.fromkeys(self.spec.link_parameters, '')
        assert set(declared) == set(CONTRACT_ARGUMENTS) | set(links)
        for name, default in {**CONTRACT_ARGUMENTS, **links}.items():
            if default is not None:
                assert declared[name] == default, name
        assert declared['description_file'] == str(
            share(self.package, 'urdf', f'{self.package}.urdf'))

    def test_the_link_arguments_are_the_link_parameters_the_node_declares(self) -> None:
        """``DriverSpec.link_parameters`` (the launch file's link arguments) are exactly the
        registry's LINK_ARGUMENTS the running node declares."""
        from gimbal_driver_common.registry import LINK_ARGUMENTS

        declared = declared_parameters(self.package) & set(LINK_ARGUMENTS)
        assert set(self.spec.link_parameters) == declared, (
            f'{self.package}: registration.py link_parameters {self.spec.link_parameters}, '
            f'but the node declares {sorted(declared)}')

    def test_link_and_log_level_arguments_override_the_parameters_file_only_when_given(
            self, launch: Any, tmp_path: Path) -> None:
        """Each link argument given beats the parameters file (the dict after the file, rcl's
        later-wins); not given, the file's value holds and the dict does not name it;
        ``log_level`` becomes ``--ros-args --log-level`` ahead of the parameters."""
        names = self.spec.link_parameters
        params = tmp_path / 'robot.yaml'
        params.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
            'publish_rate': 20.0, **{n: FILE_LINK[n] for n in names}}}}))
        given = {n: GIVEN_LINK[n][0] for n in names}
        node = self.run_launch(launch, {'params_file': str(params), 'log_level': 'debug',
                                        **given}, tmp_path).launched[-1]
        assert node.parameters[0] == params
        assert {n: node.parameters[1][n] for n in names} == {
            n: GIVEN_LINK[n][1] for n in names}
        assert launch.node_parameters(node.cmd) == {
            'publish_rate': 20.0, **node.parameters[1]}
        reserved = len(node.cmd) - node.cmd[::-1].index('--ros-args') - 1
        assert node.cmd[1:4] == ['--ros-args', '--log-level', 'debug'] and reserved == 4
        for name in names:  # one given alone: only it is overridden
            node = self.run_launch(launch, {'params_file': str(params),
                                            name: GIVEN_LINK[name][0]}, tmp_path).launched[-1]
            assert launch.node_parameters(node.cmd) == {
                'publish_rate': 20.0, **{n: FILE_LINK[n] for n in names},
                name: GIVEN_LINK[name][1], 'autostart': True,
                'description_file': node.parameters[1]['description_file']}
        node = self.run_launch(launch, {'params_file': str(params)}, tmp_path).launched[-1]
        assert not set(node.parameters[1]) & set(GIVEN_LINK), node.parameters[1]
        assert '--log-level' not in node.cmd and node.cmd.count('--ros-args') == 1
        for name in ('port', 'baudrate'):
            if name in names:
                with pytest.raises(ValueError, match=f"{name}:='fast': expected an integer"):
                    self.run_launch(launch, {name: 'fast'}, tmp_path)
        with pytest.raises(ValueError, match="log_level:='loud'"):
            self.run_launch(launch, {'log_level': 'loud'}, tmp_path)

    def test_a_bare_launch_starts_the_driver(self, launch: Any, tmp_path: Path) -> None:
        from gimbal_driver_testing import find_executable

        pkg, spec = self.package, self.spec
        context = self.run_launch(launch, params_dir=tmp_path)
        assert not context.warnings, context.warnings
        assert [started.kind for started in context.launched] == ['lifecycle_node']
        node = context.launched[0]
        assert (node.package, node.executable, node.name, node.namespace) == (
            pkg, spec.node_executable, spec.node_name, '/')
        assert node.cmd[0] == find_executable(pkg, spec.node_executable)
        params_file, given = node.parameters
        assert params_file == share(pkg, 'config', f'{pkg}.yaml')
        assert given == {'autostart': True,
                         'description_file': str(share(pkg, 'urdf', f'{pkg}.urdf'))}
        # launch_ros' command line: the file, then the dict in a file of its own, in order
        files = [node.cmd[i + 1] for i, part in enumerate(node.cmd) if part == '--params-file']
        assert files[0] == str(params_file) and len(files) == 2
        assert yaml.safe_load(Path(files[1]).read_text()) == {
            f'/{spec.node_name}': {'ros__parameters': given}}
        unknown = set(given) - declared_parameters(pkg)
        assert not unknown, f'the launch file sets undeclared parameters {unknown}'

    def test_launch_arguments_reach_the_node(self, launch: Any, tmp_path: Path) -> None:
        pkg = self.package
        params = tmp_path / 'robot.yaml'
        params.write_text(yaml.safe_dump({'/**': {'ros__parameters': {'publish_rate': 20.0}}}))
        urdf = tmp_path / 'mine.urdf'
        urdf.write_text(share(pkg, 'urdf', f'{pkg}.urdf').read_text())
        context = self.run_launch(launch, {
            'autostart': 'True', 'namespace': NAMESPACE, 'params_file': str(params),
            'description_file': str(urdf)}, tmp_path)
        node = context.launched[0]
        assert node.namespace == f'/{NAMESPACE}' and f'__ns:=/{NAMESPACE}' in node.cmd
        assert node.parameters == [params, {'autostart': True, 'description_file': str(urdf)}]
        resolved = launch.node_parameters(node.cmd)
        assert resolved == {'publish_rate': 20.0, 'autostart': True,
                            'description_file': str(urdf)}
        with pytest.raises(ValueError, match="autostart:='yes'"):
            self.run_launch(launch, {'autostart': 'yes'}, tmp_path)

    def test_use_description_starts_robot_state_publisher_with_the_urdf(
            self, launch: Any, tmp_path: Path) -> None:
        from gimbal_driver_common.kinematics import AimingChain

        context = self.run_launch(launch, {'use_description': 'true', 'namespace': 'cam'},
                                  tmp_path)
        driver, publisher = context.launched
        assert (publisher.package, publisher.executable, publisher.namespace) == (
            'robot_state_publisher', 'robot_state_publisher', '/cam')
        xml = publisher.parameters[0]['robot_description']
        assert AimingChain.from_xml(xml).base_frame == 'base_link'  # the package's URDF
        # the node aims ~/look_at with the same file robot_state_publisher publishes
        source = driver.parameters[1]['description_file']
        assert source == str(share(self.package, 'urdf', f'{self.package}.urdf'))
        assert Path(source).read_text() == xml

    @pytest.mark.parametrize('config', ['hardware', 'sim'])
    def test_config_is_keyed_for_any_namespace_and_sets_only_declared_parameters(
            self, config: str) -> None:
        name = f'{self.package}.yaml' if config == 'hardware' else f'{self.package}_sim.yaml'
        parameters = file_parameters(share(self.package, 'config', name))
        unknown = set(parameters) - declared_parameters(self.package)
        assert not unknown, f'{name} sets parameters the node does not declare: {unknown}'

    @pytest.mark.parametrize('sim', [False, True], ids=['hardware_yaml', 'sim_yaml'])
    def test_a_namespaced_launch_applies_the_parameter_file(
            self, launch: Any, sim: bool, tmp_path: Path) -> None:
        """`ros2 launch <pkg> <pkg>.launch.py namespace:=robot/gimbal autostart:=false
        [sim:=true]`: the node, started from the launch's command line (only the node: it
        is not configured, so it needs no simulator), holds every value of the YAML and of
        the launch's own dict when asked over ROS, and stays unconfigured with no link open:
        the hardware YAML names the factory address, which must never be dialled here."""
        from lifecycle_msgs.srv import GetState
        from rcl_interfaces.srv import GetParameters
        from rclpy.parameter import parameter_value_to_python

        from gimbal_driver_testing import DomainLease, ManagedProcess, ros_env
        from gimbal_driver_testing.ros import RosTestClient

        pkg, spec = self.package, self.spec
        # with the simulator YAML also log_level:=debug, which the process then shows
        context = self.run_launch(launch, {'namespace': NAMESPACE, 'autostart': 'false',
                                           'sim': 'true' if sim else 'false',
                                           'log_level': 'debug' if sim else ''}, tmp_path)
        node = context.launched[-1]
        assert node.kind == 'lifecycle_node' and node.namespace == f'/{NAMESPACE}'
        yaml_file = share(pkg, 'config', f'{pkg}_sim.yaml' if sim else f'{pkg}.yaml')
        assert node.parameters[0] == yaml_file
        expected = {**file_parameters(yaml_file), **node.parameters[1]}
        assert expected['autostart'] is False
        # the rules of rcl and rclpy, modelled ...
        assert launch.node_parameters(node.cmd) == expected
        # ... and rclpy itself: the node as launch would start it
        full_name = f'/{NAMESPACE}/{spec.node_name}'
        with DomainLease() as domain:
            process = ManagedProcess(node.cmd, ros_env(domain), name=spec.node_executable)
            try:
                with RosTestClient(domain, 'namespace_check') as ros:
                    reply = ros.call(GetParameters, f'{full_name}/get_parameters',
                                     GetParameters.Request(names=list(expected)),
                                     timeout=60)
                    state = ros.call(GetState, f'{full_name}/get_state', GetState.Request(),
                                     timeout=30)
                assert state.current_state.label == 'unconfigured'
                held = open_links(process.process.pid)
                assert not held, f'{pkg} opened a link before configure: {held}'
            finally:
                process.stop()
        # rcl's DEBUG lines on the console: the node's log level is the one given, else INFO
        debug = re.search(r'^\[DEBUG\] \[[\d.]+\] \[', process.output(), re.MULTILINE)
        assert bool(debug) is sim, process.output()[-2000:]
        got = {name: parameter_value_to_python(value)
               for name, value in zip(expected, reply.values, strict=True)}
        wrong = {name: (got[name], want) for name, want in expected.items()
                 if not same_value(got[name], want)}
        assert not wrong, f'{full_name} does not hold the values of {yaml_file.name}: {wrong}'

    @pytest.mark.parametrize('autostart', [None, 'false'], ids=['bare', 'autostart_false'])
    def test_sim_true_starts_the_simulator_and_the_node_connects_to_it(
            self, launch: Any, autostart: str | None, tmp_path: Path) -> None:
        """``sim:=true``: the simulator (not a ROS node: no --ros-args) and the node with the
        simulator YAML, whose link address is the one the simulator serves. Both are then
        started from the command lines the launch produced; only the fixed address (TCP port
        or pty path) is swapped for a private one, in both, so runs side by side do not meet.

        A bare launch (no ``autostart`` argument) ends with an active node publishing
        joint_states; ``autostart:=false`` leaves it unconfigured, and a lifecycle manager's
        configure and activate then bring it up."""
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import GetState
        from sensor_msgs.msg import JointState

        from gimbal_driver_common.registry import parameter_arguments
        from gimbal_driver_common.sim_control import parse_ready_line
        from gimbal_driver_testing import (
            DomainLease,
            ManagedProcess,
            find_executable,
            free_tcp_port,
            ros_env,
            wait_for,
        )
        from gimbal_driver_testing.ros import RosTestClient

        pkg, spec = self.package, self.spec
        arguments = {'sim': 'true'} if autostart is None else {'sim': 'true',
                                                               'autostart': autostart}
        simulator, node = self.run_launch(launch, arguments, tmp_path).launched
        assert simulator.kind == 'process' and '--ros-args' not in simulator.cmd
        assert simulator.cmd == [find_executable(pkg, spec.sim_executable),
                                 *spec.launch_sim_arguments]
        sim_yaml = share(pkg, 'config', f'{pkg}_sim.yaml')
        assert node.parameters[0] == sim_yaml
        assert node.parameters[1]['autostart'] is (autostart is None)
        option = next(o for o in ('--port', '--link') if o in simulator.cmd)
        address = simulator.cmd[simulator.cmd.index(option) + 1]
        parameters = file_parameters(sim_yaml)
        keys = [k for k, v in parameters.items() if str(v) == address]
        assert keys, f'{sim_yaml.name} must name the simulator address {address}'
        private = free_tcp_port() if option == '--port' else str(tmp_path / 'link')
        sim_cmd = [str(private) if part == address else part for part in simulator.cmd]
        # the private address given as the launch's link argument(s), over the sim YAML
        # (a key that is no link argument, Kessler's discovery_port, as -p: later wins)
        links = [k for k in keys if k in spec.link_parameters]
        assert links, f'{keys}: none is a link argument {spec.link_parameters}'
        node = self.run_launch(launch, {**arguments, **dict.fromkeys(links, str(private))},
                               tmp_path).launched[-1]
        assert {k: node.parameters[1][k] for k in links} == dict.fromkeys(links, private)
        others = parameter_arguments(dict.fromkeys(set(keys) - set(links), private))
        with DomainLease() as domain:
            sim = ManagedProcess(sim_cmd, ros_env(domain), name=spec.sim_executable)
            started = None
            try:
                wait_for(lambda: parse_ready_line(sim.output()) or not sim.running, 30.0,
                         f'{spec.sim_executable} to be ready')
                assert sim.running, sim.output()[-2000:]
                # the launch's command line: the link argument reaches rclpy
                started = ManagedProcess([*node.cmd, *others], ros_env(domain),
                                         name=spec.node_executable)
                with RosTestClient(domain, 'launch_sim_check') as ros:
                    if autostart is None:
                        ros.wait_for_lifecycle_state(spec.node_name, 'active', timeout=60)
                    else:
                        # once it answers, it is unconfigured, and stays so until told
                        state = ros.call(GetState, f'/{spec.node_name}/get_state',
                                         GetState.Request(), timeout=60)
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
