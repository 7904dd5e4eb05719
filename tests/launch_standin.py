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
  are executed (launch_ros/launch_ros/actions/node.py, ``Node._perform_substitutions``);
  a dict value that is a substitution is performed and read as YAML
  (launch_ros/launch_ros/utilities/evaluate_parameters.py, ``evaluate_parameter_dict``), a
  parameter file is a path that must be a file (else a warning and it is left out);
  ``LifecycleNode`` takes ``name`` and ``namespace`` as required keywords
  (launch_ros/launch_ros/actions/lifecycle_node.py). Every ``Node`` command line gets
  ``--ros-args`` (node.py ``Node.__init__``), so a program that is not a ROS node runs
  through ``ExecuteProcess`` with ``ExecutableInPackage``
  (launch_ros/launch_ros/substitutions/executable_in_package.py: the executable in
  ``<prefix>/lib/<package>``, else ``SubstitutionFailure``).

``install()`` puts these classes in ``sys.modules`` under the real module names; each
executed process is recorded as a :class:`Launched` (its command line and, for nodes, the
resolved parameters) in the order launch would start them.
"""

from __future__ import annotations

import importlib.util
import sys
import types
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from gimbal_driver_common.testing import find_executable

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
    def __init__(self) -> None:
        self.launch_configurations: dict[str, str] = {}
        self.launched: list[Launched] = []
        self.warnings: list[str] = []


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
        self.arguments, self.ros_arguments = list(arguments or []), list(ros_arguments or [])

    def execute(self, context: LaunchContext) -> None:
        package = perform(context, self.package) if self.package is not None else ''
        executable = perform(context, self.executable)
        name = perform(context, self.name) if self.name is not None else None
        namespace = perform(context, self.namespace) if self.namespace is not None else ''
        if namespace and not namespace.startswith('/'):
            namespace = '/' + namespace  # make_namespace_absolute
        parameters: list[Path | dict[str, Any]] = []
        for entry in self.parameters:
            if isinstance(entry, dict):
                parameters.append({perform(context, k): _yaml_value(context, str(k), v)
                                   for k, v in entry.items()})
                continue
            path = Path(perform(context, entry))
            if not path.is_file():
                context.warnings.append(f'Parameter file path is not a file: {path}')
                continue
            parameters.append(path)
        remappings = [(perform(context, a), perform(context, b)) for a, b in self.remappings]
        path = (find_executable(package, executable) if package not in NOT_HERE
                else f'{package}/lib/{executable}') if package else executable
        cmd = [path, *(perform(context, a) for a in self.arguments), '--ros-args',
               *(perform(context, a) for a in self.ros_arguments)]
        if name is not None:
            cmd += ['-r', f'__node:={name}']
        if namespace:
            cmd += ['-r', f'__ns:={namespace}']
        context.launched.append(Launched(self.kind, cmd, package, executable, name, namespace,
                                         parameters, remappings))


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


def run(description: LaunchDescription, arguments: dict[str, str] | None = None
        ) -> LaunchContext:
    """Launch ``description`` as `ros2 launch ... name:=value` would; the context records
    what was started (``launched``) and the warnings launch would log."""
    context = LaunchContext()
    entities: list[object] = [SetLaunchConfiguration(k, v) for k, v in (arguments or {}).items()]
    entities.append(description)
    for entity in entities:
        _visit(entity, context)
    return context


def _visit(entity: object, context: LaunchContext) -> None:
    for sub_entity in entity.visit(context) or ():
        _visit(sub_entity, context)

