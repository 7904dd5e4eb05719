"""A strict stand-in for ROS 2 Jazzy's ``launch`` and ``launch_ros`` (not installable here).

``ros2 launch`` is not available in the pip environment, so the launch files run against
these classes, which execute the actions **in order, as launch does** (each rule follows
the jazzy branch of ros2/launch and ros2/launch_ros, file and function named below):

* ``ros2 launch PKG FILE name:=value`` includes the file with its arguments, which become
  launch configurations *before* the description is visited
  (launch/launch/actions/include_launch_description.py, ``IncludeLaunchDescription.execute``:
  one ``SetLaunchConfiguration`` per argument, then the description).
* Entities are visited depth first, in order; what an action's ``execute`` returns is
  visited right after it, before its next sibling
  (launch/launch/utilities/visit_all_entities_and_collect_futures_impl.py,
  launch/launch/launch_description.py ``LaunchDescription.visit``).
* ``DeclareLaunchArgument`` sets its configuration when it is executed, to its default if
  the argument was not given, and raises for a missing required one or a value outside its
  choices (launch/launch/actions/declare_launch_argument.py, ``execute``).
* ``LaunchConfiguration.perform`` raises ``SubstitutionFailure("launch configuration 'x'
  does not exist")`` for a configuration not set yet and no default
  (launch/launch/substitutions/launch_configuration.py, ``perform``): a read before the
  declaration is executed fails, as `ros2 launch` did with the old U-Camera file.
* ``OpaqueFunction`` calls its function when it is reached
  (launch/launch/actions/opaque_function.py, ``execute``).
* ``Node``/``LifecycleNode`` resolve name, namespace, parameters and remappings when they
  are executed and build the command line as launch_ros does
  (launch_ros/launch_ros/actions/node.py, ``Node.__init__``, ``Node._perform_substitutions``
  and ``Node.execute``): ``<exe> [arguments] [--ros-args ros_arguments] --ros-args
  [-r __node:=NAME] [-r __ns:=NS] [--params-file FILE]... [-r FROM:=TO]...``. The namespace
  is made absolute (launch_ros/utilities/namespace_utils.py, ``prefix_namespace`` and
  ``make_namespace_absolute``: ``''`` becomes ``/``). Each entry of ``parameters`` becomes one
  ``--params-file`` in order: a path as it is (one that is not a file: a warning, left out),
  a dict written to a temporary file keyed with the node's full name when name and namespace
  are both given, else ``/**`` (node.py ``_create_params_file_from_dict``); a dict value that
  is a substitution is performed and read as YAML
  (launch_ros/launch_ros/utilities/evaluate_parameters.py, ``evaluate_parameter_dict``),
  a plain str, int, float or bool keeps its type (a str is ``yaml.dump``-ed and read back
  as the same string: launch_ros/launch_ros/utilities/normalize_parameters.py,
  ``normalize_parameter_dict``). ``ros_arguments`` given (even empty) add ``--ros-args``
  and them ahead of the ``--ros-args`` launch_ros reserves (node.py ``Node.__init__``), so
  ``--log-level`` reaches rcl.
  ``LifecycleNode`` takes ``name`` and ``namespace`` as required keywords
  (launch_ros/launch_ros/actions/lifecycle_node.py). Every ``Node`` command line gets
  ``--ros-args``, so a program that is not a ROS node runs
  through ``ExecuteProcess`` with ``ExecutableInPackage``
  (launch_ros/launch_ros/substitutions/executable_in_package.py: the executable in
  ``<prefix>/lib/<package>``, else ``SubstitutionFailure``).

:func:`node_parameters` then says what the started node gets from that command line, by
rcl's and rclpy's rules: every ``--params-file`` and ``-p`` goes, in command-line order, into
one table of node-name keys (rcl/src/rcl/arguments.c ``_rcl_parse_param_file`` and
``_rcl_parse_param_rule``, a ``-p`` being keyed ``/**``; rcl_yaml_param_parser/src/parse.c
``parse_key``: nested keys above ``ros__parameters`` are joined with ``/``, ``find_node``
keeps the keys in the order first seen), and a node takes, key by key in that order, the
values of every key that matches its full name with ``/*`` read as one ``/name`` and ``/**``
as any run of them (rclpy/src/rclpy/node.cpp ``_populate_node_parameters_from_rcl_params``:
a key without a leading ``/`` gets one; ``std::regex_match`` of the rewritten key). A file
keyed ``capture_driver:`` therefore reaches ``/capture_driver`` only, never
``/robot/gimbal/capture_driver``.

The tests start the real node from :attr:`Launched.cmd` too, so rclpy itself applies the files.

``install()`` puts these classes in ``sys.modules`` under the real module names; each
executed process is recorded as a :class:`Launched` (its command line and, for nodes, the
resolved parameters) in the order launch would start them.
"""

from __future__ import annotations

import importlib.util
import re
import sys
import tempfile
import types
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from gimbal_driver_testing import find_executable

#: packages of a full ROS 2 install that the pip environment lacks: their executables are not
#: looked up (ours are: a launch file naming a missing executable fails)
NOT_HERE = frozenset({'robot_state_publisher'})


class SubstitutionFailure(RuntimeError):
    """launch.substitutions.substitution_failure.SubstitutionFailure."""


@dataclass
class Launched:
    """A process launch would start: its command, and for nodes what was resolved."""

    kind: str                       # 'process', 'node' or 'lifecycle_node'
    cmd: list[str]
    package: str = ''
    executable: str = ''
    name: str | None = None
    namespace: str = ''
    parameters: list[Path | dict[str, Any]] = field(default_factory=list)
    remappings: list[tuple[str, str]] = field(default_factory=list)


class LaunchContext:
    def __init__(self, params_dir: Path | None = None) -> None:
        self.launch_configurations: dict[str, str] = {}
        self.launched: list[Launched] = []
        self.warnings: list[str] = []
        #: where dict parameters are written (launch_ros: NamedTemporaryFile in the temp dir)
        self.params_dir = params_dir


def perform(context: LaunchContext, value: object) -> str:
    """launch.utilities.perform_substitutions over a text, a substitution or a list of them."""
    if isinstance(value, str):
        return value
    if isinstance(value, Substitution):
        return value.perform(context)
    if isinstance(value, (list, tuple)):
        return ''.join(perform(context, item) for item in value)
    raise TypeError(f'not a substitution: {value!r}')


class Substitution:
    def perform(self, context: LaunchContext) -> str:
        raise NotImplementedError


class TextSubstitution(Substitution):
    def __init__(self, *, text: str) -> None:
        self.text = text

    def perform(self, context: LaunchContext) -> str:
        return self.text


class LaunchConfiguration(Substitution):
    def __init__(self, variable_name: object, *, default: object = None) -> None:
        self.variable_name, self.default = variable_name, default

    def perform(self, context: LaunchContext) -> str:
        name = perform(context, self.variable_name)
        if name not in context.launch_configurations:
            if self.default is None:
                raise SubstitutionFailure(f"launch configuration '{name}' does not exist")
            return perform(context, self.default)
        return context.launch_configurations[name]


class ExecutableInPackage(Substitution):
    def __init__(self, executable: object, package: object) -> None:
        self.executable, self.package = executable, package

    def perform(self, context: LaunchContext) -> str:
        package, executable = perform(context, self.package), perform(context, self.executable)
        try:
            return find_executable(package, executable)
        except FileNotFoundError as exc:
            raise SubstitutionFailure(str(exc)) from None


class Action:
    def __init__(self, *, condition: object = None) -> None:
        if condition is not None:
            raise NotImplementedError('conditions are not modelled by this stand-in')

    def visit(self, context: LaunchContext) -> list[object] | None:
        return self.execute(context)

    def execute(self, context: LaunchContext) -> list[object] | None:
        return None


class LaunchDescription:
    def __init__(self, initial_entities: Iterable[object] | None = None) -> None:
        self.entities = list(initial_entities or [])

    def visit(self, context: LaunchContext) -> list[object]:
        return self.entities

    def declared_arguments(self) -> list[DeclareLaunchArgument]:
        """What `ros2 launch --show-args` lists: the declarations visible without launching
        (launch_description.py ``get_launch_arguments``; an OpaqueFunction hides its own)."""
        return [e for e in self.entities if isinstance(e, DeclareLaunchArgument)]


class DeclareLaunchArgument(Action):
    def __init__(self, name: str, *, default_value: object = None, description: str | None = None,
                 choices: Sequence[str] | None = None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.name, self.default_value = name, default_value
        self.description, self.choices = description or 'no description given', choices

    def execute(self, context: LaunchContext) -> None:
        if self.name not in context.launch_configurations:
            if self.default_value is None:
                raise RuntimeError(f'Required launch argument "{self.name}" was not provided.')
            context.launch_configurations[self.name] = perform(context, self.default_value)
        value = context.launch_configurations[self.name]
        if self.choices is not None and value not in self.choices:
            raise RuntimeError(f'Argument "{self.name}" provided value "{value}" is not valid. '
                               f'Valid options are: {list(self.choices)}')


class SetLaunchConfiguration(Action):
    def __init__(self, name: object, value: object, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.name, self.value = name, value

    def execute(self, context: LaunchContext) -> None:
        context.launch_configurations[perform(context, self.name)] = perform(context, self.value)


class OpaqueFunction(Action):
    def __init__(self, *, function: Callable[..., Any], args: Sequence[object] | None = None,
                 kwargs: dict[str, object] | None = None, **other: Any) -> None:
        super().__init__(**other)
        self.function, self.args, self.kwargs = function, list(args or []), dict(kwargs or {})

    def execute(self, context: LaunchContext) -> list[object] | None:
        return self.function(context, *self.args, **self.kwargs)


class ExecuteProcess(Action):
    def __init__(self, *, cmd: Sequence[object], name: object = None, output: str = 'log',
                 **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.cmd, self.process_name, self.output = list(cmd), name, output

    def execute(self, context: LaunchContext) -> None:
        context.launched.append(Launched('process', [perform(context, c) for c in self.cmd]))


def _yaml_value(context: LaunchContext, name: str, value: object) -> object:
    """evaluate_parameter_dict: a substitution is performed, then read as YAML."""
    if isinstance(value, Substitution) or (
            isinstance(value, (list, tuple)) and value and isinstance(value[0], Substitution)):
        text = perform(context, value)
        loaded = yaml.safe_load(text if text else "''")
        if not isinstance(loaded, (bool, int, float, str, bytes, list)):
            raise TypeError(f'Allowed value types are bytes, bool, int, float, str, Sequence; '
                            f'got {type(loaded)} for "{name}"')
        return loaded
    if isinstance(value, dict):
        return {k: _yaml_value(context, f'{name}.{k}', v) for k, v in value.items()}
    if not isinstance(value, (bool, int, float, str, bytes, list, tuple)):
        raise TypeError(f'parameter {name!r}: {value!r} is not a parameter value')
    return value


class Node(Action):
    kind = 'node'

    def __init__(self, *, executable: object, package: object = None, name: object = None,
                 namespace: object = None, exec_name: object = None,
                 parameters: Sequence[object] | None = None,
                 remappings: Sequence[tuple[object, object]] | None = None,
                 ros_arguments: Sequence[object] | None = None,
                 arguments: Sequence[object] | None = None, output: str = 'log',
                 **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if parameters is not None and (isinstance(parameters, str)
                                       or not isinstance(parameters, Sequence)):
            raise TypeError(f'Expecting list of parameters, got {parameters}')
        self.executable, self.package, self.name, self.namespace = (executable, package, name,
                                                                    namespace)
        self.parameters, self.remappings = list(parameters or []), list(remappings or [])
        self.arguments = list(arguments or [])
        self.ros_arguments = None if ros_arguments is None else list(ros_arguments)

    def execute(self, context: LaunchContext) -> None:
        package = perform(context, self.package) if self.package is not None else ''
        executable = perform(context, self.executable)
        name = perform(context, self.name) if self.name is not None else None
        namespace = (perform(context, self.namespace) if self.namespace is not None
                     else None)
        namespace = _absolute(_prefix(context.launch_configurations.get('ros_namespace'),
                                      namespace))
        full_name = (None if name is None or namespace is None
                     else _prefix(namespace, name))
        parameters: list[Path | dict[str, Any]] = []
        files: list[str] = []
        for entry in self.parameters:
            if isinstance(entry, dict):
                values = {perform(context, k): _yaml_value(context, str(k), v)
                          for k, v in entry.items()}
                parameters.append(values)
                files.append(_params_file(context, full_name, values))
                continue
            path = Path(perform(context, entry))
            if not path.is_file():
                context.warnings.append(f'Parameter file path is not a file: {path}')
                continue
            parameters.append(path)
            files.append(str(path))
        remappings = [(perform(context, a), perform(context, b)) for a, b in self.remappings]
        path = (find_executable(package, executable) if package not in NOT_HERE
                else f'{package}/lib/{executable}') if package else executable
        cmd = [path, *(perform(context, a) for a in self.arguments)]
        if self.ros_arguments is not None:  # [] too: a bare --ros-args (Node.__init__)
            cmd += ['--ros-args', *(perform(context, a) for a in self.ros_arguments)]
        cmd.append('--ros-args')
        if name is not None:
            cmd += ['-r', f'__node:={name}']
        if namespace is not None:
            cmd += ['-r', f'__ns:={namespace}']
        for file in files:
            cmd += ['--params-file', file]
        for source, target in remappings:
            cmd += ['-r', f'{source}:={target}']
        context.launched.append(Launched(self.kind, cmd, package, executable, name,
                                         namespace or '', parameters, remappings))


def _prefix(base: str | None, namespace: str | None) -> str | None:
    """namespace_utils.prefix_namespace."""
    if base is None and namespace is None:
        return None
    if namespace is None:
        combined = base
    elif not base or namespace.startswith('/'):
        combined = namespace
    else:
        combined = ('' if base == '/' else base) + '/' + namespace
    return combined if combined == '/' else combined.rstrip('/')


def _absolute(namespace: str | None) -> str | None:
    """namespace_utils.make_namespace_absolute."""
    if namespace is None or namespace.startswith('/'):
        return namespace
    return '/' + namespace


def _params_file(context: LaunchContext, full_name: str | None,
                 values: dict[str, Any]) -> str:
    """Node._create_params_file_from_dict: the dict under the node's full name (``/**``
    when launch does not know it), in a file of its own."""
    with tempfile.NamedTemporaryFile('w', prefix='launch_params_', delete=False,
                                     dir=context.params_dir) as handle:
        yaml.dump({full_name or '/**': {'ros__parameters': values}}, handle,
                  default_flow_style=False)
        return handle.name


def _key_matches(key: str, full_name: str) -> bool:
    """rclpy node.cpp _populate_node_parameters_from_rcl_params: '/' prepended if missing,
    then every ``/*`` replaced by ``(/\\w+)`` (so ``/**`` becomes ``(/\\w+)*``) and the
    result used as a regular expression that must match the whole full name."""
    key = key if key.startswith('/') else '/' + key
    return re.fullmatch(key.replace('/*', r'(/\w+)'), full_name) is not None


def _flatten(prefix: str, value: object, into: dict[str, Any]) -> None:
    """Nested parameter maps become dotted names (parse.c: the parameter namespace)."""
    if isinstance(value, dict):
        for key, sub in value.items():
            _flatten(f'{prefix}.{key}' if prefix else str(key), sub, into)
    else:
        into[prefix] = value


def _node_sections(document: dict[str, Any], above: str = '') -> list[tuple[str, dict]]:
    """(node key, flat parameters) of a parameters file, keys above ros__parameters joined
    with '/' (parse.c parse_key, MAP_NODE_NAME_LVL)."""
    sections: list[tuple[str, dict]] = []
    for key, value in document.items():
        name = f'{above}/{key}' if above else str(key)
        if not isinstance(value, dict):
            raise ValueError(f'{name}: no ros__parameters under a node name')
        if 'ros__parameters' in value:
            flat: dict[str, Any] = {}
            _flatten('', value['ros__parameters'] or {}, flat)
            sections.append((name, flat))
        others = {k: v for k, v in value.items() if k != 'ros__parameters'}
        sections += _node_sections(others, name) if others else []
    return sections


def node_parameters(cmd: Sequence[str], full_name: str | None = None) -> dict[str, Any]:
    """The parameter overrides rclpy gives the node that ``cmd`` starts (its full name from
    ``__node``/``__ns`` in ``cmd`` unless given), by the rules in this module's docstring."""
    node, namespace = Path(cmd[0]).name, '/'
    table: dict[str, dict[str, Any]] = {}  # key -> values, in the order keys were first seen
    i = 0
    while i < len(cmd):
        if cmd[i] == '-r' and cmd[i + 1].startswith('__node:='):
            node = cmd[i + 1].split(':=', 1)[1]
        elif cmd[i] == '-r' and cmd[i + 1].startswith('__ns:='):
            namespace = cmd[i + 1].split(':=', 1)[1]
        elif cmd[i] == '--params-file':
            document = yaml.safe_load(Path(cmd[i + 1]).read_text()) or {}
            for key, values in _node_sections(document):
                table.setdefault(key, {}).update(values)
        elif cmd[i] == '-p':
            name, _, value = cmd[i + 1].partition(':=')
            table.setdefault('/**', {})[name] = yaml.safe_load(value)
        i += 2 if cmd[i] in ('-r', '--params-file', '-p') else 1
    full_name = full_name or _prefix(namespace, node)
    resolved: dict[str, Any] = {}
    for key, values in table.items():
        if _key_matches(key, full_name):
            resolved.update(values)
    return resolved


class LifecycleNode(Node):
    kind = 'lifecycle_node'

    def __init__(self, *, name: object, namespace: object, **kwargs: Any) -> None:
        super().__init__(name=name, namespace=namespace, **kwargs)


MODULES = {
    'launch': {'LaunchDescription': LaunchDescription, 'LaunchContext': LaunchContext,
               'Action': Action, 'Substitution': Substitution},
    'launch.actions': {'DeclareLaunchArgument': DeclareLaunchArgument,
                       'OpaqueFunction': OpaqueFunction, 'ExecuteProcess': ExecuteProcess,
                       'SetLaunchConfiguration': SetLaunchConfiguration},
    'launch.substitutions': {'LaunchConfiguration': LaunchConfiguration,
                             'TextSubstitution': TextSubstitution},
    'launch.substitutions.substitution_failure': {'SubstitutionFailure': SubstitutionFailure},
    'launch_ros': {},
    'launch_ros.actions': {'Node': Node, 'LifecycleNode': LifecycleNode},
    'launch_ros.substitutions': {'ExecutableInPackage': ExecutableInPackage},
}


def install(monkeypatch: Any) -> None:
    """Put the stand-in modules in ``sys.modules`` (pytest's monkeypatch undoes it); a name
    they do not have fails the import, as a name the real modules lack would."""
    for module_name, names in MODULES.items():
        module = types.ModuleType(module_name)
        module.__dict__.update(names)
        module.__path__ = []  # a package, so its submodules import
        monkeypatch.setitem(sys.modules, module_name, module)
    # the launch helpers import launch at their own import: load them fresh on these
    monkeypatch.delitem(sys.modules, 'gimbal_driver_common.ros.description_launch',
                        raising=False)


def load_description(path: Path) -> LaunchDescription:
    """``generate_launch_description()`` of a launch file (launch_description_sources)."""
    spec = importlib.util.spec_from_file_location(f'launch_under_test_{path.stem}', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.generate_launch_description()


def run(description: LaunchDescription, arguments: dict[str, str] | None = None,
        params_dir: Path | None = None) -> LaunchContext:
    """Launch ``description`` as `ros2 launch ... name:=value` would; the context records
    what was started (``launched``) and the warnings launch would log. Dict parameters are
    written to ``params_dir`` (default: the temp dir, as launch_ros does)."""
    context = LaunchContext(params_dir)
    entities: list[object] = [SetLaunchConfiguration(k, v) for k, v in (arguments or {}).items()]
    entities.append(description)
    for entity in entities:
        _visit(entity, context)
    return context


def _visit(entity: object, context: LaunchContext) -> None:
    for sub_entity in entity.visit(context) or ():
        _visit(sub_entity, context)

