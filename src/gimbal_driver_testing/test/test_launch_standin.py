"""The launch stand-in (gimbal_driver_testing.launch_standin) is strict where
`ros2 launch` is, builds the command line launch_ros builds, and applies parameter files
to a node by rcl's and rclpy's rules, so the launch tests of each driver package can fail."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from gimbal_driver_testing import launch_standin


@pytest.fixture
def launch(monkeypatch: pytest.MonkeyPatch):
    launch_standin.install(monkeypatch)
    return launch_standin


def a_node(launch, **options):
    """A Node of no package (its executable is taken as the path, as launch_ros does)."""
    return launch.Node(executable='some_node', **options)


def test_reading_a_launch_configuration_before_its_declaration_fails(launch) -> None:
    """A configuration read before the action that declares it has run does not exist."""
    def read_it(context: object) -> list[object]:
        return [a_node(launch, parameters=[{'x': launch.LaunchConfiguration('x')}])]

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


@pytest.mark.parametrize(('ros_arguments', 'head'), [
    (None, ['some_node', '--ros-args', '-r']),
    ([], ['some_node', '--ros-args', '--ros-args', '-r']),
    (['--log-level', 'debug'], ['some_node', '--ros-args', '--log-level', 'debug',
                                '--ros-args', '-r']),
])
def test_ros_arguments_go_ahead_of_the_reserved_ros_args(launch, ros_arguments, head) -> None:
    """launch_ros node.py ``Node.__init__``: ``ros_arguments`` given (even empty) add
    ``--ros-args`` and them before the ``--ros-args`` for name, namespace and parameters."""
    started = launch.run(launch.LaunchDescription([a_node(
        launch, name='n', ros_arguments=ros_arguments)])).launched[0]
    assert started.cmd[:len(head)] == head


def test_plain_dict_values_keep_their_type(launch, tmp_path: Path) -> None:
    """normalize_parameter_dict: a str stays a string (yaml.dump, read back), an int an
    int, so a text that looks like a number is not turned into one."""
    node = launch.run(launch.LaunchDescription([a_node(
        launch, name='n', namespace='', parameters=[{'host': '10', 'port': 4950}])]),
        params_dir=tmp_path).launched[0]
    assert launch.node_parameters(node.cmd) == {'host': '10', 'port': 4950}


def test_the_command_line_is_launch_ros_one(launch, tmp_path: Path) -> None:
    params = tmp_path / 'p.yaml'
    params.write_text(yaml.safe_dump({'/**': {'ros__parameters': {'rate': 2.0}}}))
    node = launch.run(launch.LaunchDescription([a_node(
        launch, name='n', namespace='robot/gimbal', arguments=['--flag'],
        parameters=[str(params), {'a': 1}, str(tmp_path / 'missing.yaml')],
        remappings=[('in', 'out')])]), params_dir=tmp_path)
    [started] = node.launched
    files = [started.cmd[i + 1] for i, part in enumerate(started.cmd) if part == '--params-file']
    dict_file = files[1]
    assert started.cmd == ['some_node', '--flag', '--ros-args', '-r', '__node:=n',
                           '-r', '__ns:=/robot/gimbal', '--params-file', str(params),
                           '--params-file', dict_file, '-r', 'in:=out']
    # the dict under the node's full name, since launch knows both name and namespace
    assert yaml.safe_load(Path(dict_file).read_text()) == {
        '/robot/gimbal/n': {'ros__parameters': {'a': 1}}}
    assert node.warnings == [f'Parameter file path is not a file: {tmp_path / "missing.yaml"}']


def test_an_empty_namespace_is_the_root_and_no_name_keys_the_dict_any_node(
        launch, tmp_path: Path) -> None:
    [started] = launch.run(launch.LaunchDescription([a_node(
        launch, namespace='', parameters=[{'a': True}])]), params_dir=tmp_path).launched
    assert started.cmd[:4] == ['some_node', '--ros-args', '-r', '__ns:=/']
    dict_file = started.cmd[started.cmd.index('--params-file') + 1]
    assert yaml.safe_load(Path(dict_file).read_text()) == {'/**': {'ros__parameters':
                                                                   {'a': True}}}


@pytest.mark.parametrize(('key', 'applies'), [
    ('/**', True), ('/**/driver', True), ('/robot/gimbal/driver', True),
    ('robot/gimbal/driver', True), ('/*/*/driver', True),
    ('driver', False), ('/driver', False), ('/*/driver', False), ('/robot/*', False),
])
def test_keys_match_as_rclpy_matches_them(key: str, applies: bool, tmp_path: Path) -> None:
    params = tmp_path / 'p.yaml'
    params.write_text(yaml.safe_dump({key: {'ros__parameters': {'rate': 2.0}}}))
    cmd = ['driver', '--ros-args', '-r', '__ns:=/robot/gimbal', '--params-file', str(params)]
    assert launch_standin.node_parameters(cmd) == ({'rate': 2.0} if applies else {})
    # in the root namespace the bare name applies, and /** still does
    root = ['driver', '--ros-args', '--params-file', str(params)]
    assert ('rate' in launch_standin.node_parameters(root)) is (
        key in ('/**', '/**/driver', 'driver', '/driver'))


def test_later_files_and_rules_win_and_nested_keys_join(tmp_path: Path) -> None:
    first, second = tmp_path / 'a.yaml', tmp_path / 'b.yaml'
    first.write_text(yaml.safe_dump({'/**': {'ros__parameters': {'a': 1, 'b': 1,
                                                                 'nested': {'c': 3}}}}))
    second.write_text(yaml.safe_dump({'robot': {'gimbal': {'driver': {
        'ros__parameters': {'a': 2}}}}}))
    cmd = ['driver', '--ros-args', '-r', '__ns:=/robot/gimbal', '--params-file', str(first),
           '--params-file', str(second), '-p', 'b:=5']
    assert launch_standin.node_parameters(cmd) == {'a': 2, 'b': 5, 'nested.c': 3}
