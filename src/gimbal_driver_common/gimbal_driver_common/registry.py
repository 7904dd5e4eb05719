"""The driver registry: every driver package describes itself once, in a :class:`DriverSpec`.

A package registers by naming its spec in the ``gimbal_driver_common.drivers`` entry-point
group of its ``setup.py``::

    entry_points={'gimbal_driver_common.drivers': ['capture = capture_driver.registration:SPEC']}

Everything that runs "every driver" reads :func:`drivers` instead of a list of its own: the
demo (``scripts/demo.py``), the soak (``scripts/soak.py``), the benchmarks (``bench/run.py``)
and the cross-package tests in ``tests/``. A package that is not built (installed) is not
found, so it is left out everywhere.

ROS-free: a spec is plain data. What needs code (a demo step, the one in-process simulator
handle of :mod:`gimbal_driver_common.sim_handle`, the :class:`RefusedRequests` of the
driver's services) is named by a dotted reference (``module:attribute``) into the driver's
runtime package and imported only by the tool that uses it; none imports a test library.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

ENTRY_POINT_GROUP = 'gimbal_driver_common.drivers'
#: the link's main parameters (docs/interface.md), which a driver's launch file takes as
#: arguments where its node declares them: name -> (type of the parameter, what it is)
LINK_ARGUMENTS: Mapping[str, tuple[type, str]] = {
    'host': (str, 'device host name or IP address'),
    'port': (int, 'device TCP port'),
    'transport': (str, 'link to the device (tcp, serial, usb: the ones the driver has)'),
    'serial_port': (str, 'serial device, e.g. /dev/ttyUSB0'),
    'baudrate': (int, 'serial baud rate'),
    'can_interface': (str, 'python-can interface, e.g. socketcan or slcan'),
    'can_channel': (str, 'CAN channel, e.g. can0 (slcan: the serial device)'),
}
#: the package of the reference driver (the virtual gimbal); every other one is a device driver
REFERENCE_PACKAGE = 'virtual_gimbal_driver'


class RegistryError(RuntimeError):
    """A registration that does not load or does not describe a driver."""


@dataclass(frozen=True)
class DemoSettings:
    """What ``scripts/demo.py`` does with the driver besides the common script.

    ``scan``: the ``gimbal_msgs/srv/StartScan`` request fields of the scan step (None: no
    scan). ``extra_steps``: ``(label, 'module:function')``; a function takes the demo target
    and the ROS client and returns a one-line result (it raises on failure). The label
    ``home`` with no reference runs the common ``~/home`` action. ``node_parameters``: what
    the demo's node gets on top of the spec's ``node_parameters`` (the demo runs every
    simulator and node on one machine, and nothing in it is meant to go unanswered: a
    request timeout that waits for a busy machine's answer).
    """

    jog_velocity: float = 0.2
    jog_joint: str = ''   # '' = the first joint
    scan: Mapping[str, Any] | None = None
    extra_steps: tuple[tuple[str, str], ...] = ()
    node_parameters: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SoakSettings:
    """What ``scripts/soak.py`` needs beyond the in-process simulator (``sim_handle``).

    ``safe_range``: a valid joint_command target range (rad/m) inside every joint's limits;
    ``joint_ranges`` narrows it per joint. ``extra_services``: the driver's own services
    (name -> ``pkg/srv/Type``) that the random traffic calls with absurd values.
    """

    safe_range: tuple[float, float] = (-0.3, 0.3)
    joint_ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    extra_services: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class BenchSettings:
    """How ``bench/run.py`` measures the driver.

    ``module``: a benchmark module in ``bench/`` (``bench_<module>.py`` with
    ``run(domain) -> dict``) for device-specific figures (codec rates, wire limits); ''
    runs the generic benchmark, which needs the simulator handle's ``device_target`` and
    the command stream settings here: joint, first target (rad/m), tolerance of the value
    the device shows (rad/m) and two far ``~/move_to`` targets.
    """

    module: str = ''
    stream_joint: str = ''
    stream_base: float = -0.25
    stream_tolerance: float = 1e-6
    move_targets: tuple[float, float] = (-0.4, 0.4)
    publish_rate: float = 50.0
    max_rate: float = 0.0   # > 0: also the joint_states rate at this publish_rate


@dataclass(frozen=True)
class RefusedRequests:
    """The requests a driver's own services must refuse, as plain data.

    A driver's ``refused_requests`` function returns one;
    ``gimbal_driver_testing.refused_requests.strategy`` turns it into the hypothesis
    strategy the property tests draw from (``tests/test_ros_properties.py``), so the
    driver's runtime package needs no test library. Each service is named under the node.

    ``command_service``: the driver's ``gimbal_msgs/srv/DeviceCommand`` service ('' = none);
    ``refused_commands``: names it refuses whatever the axis and arguments (behind an
    opt-in parameter, or motion without the driver's limit checks); ``known_commands``:
    every name it knows (any other name, out-of-scope weapon names included, is refused).
    ``refused_triggers``: ``std_srvs/Trigger`` services refused by default.
    ``mode_service``: a ``gimbal_msgs/srv/SetMode`` service; a mode outside
    ``known_modes`` (compared stripped and lower-case) is refused.
    """

    command_service: str = ''
    refused_commands: tuple[str, ...] = ()
    known_commands: frozenset[str] = frozenset()
    refused_triggers: tuple[str, ...] = ()
    mode_service: str = ''
    known_modes: frozenset[str] = frozenset()


@dataclass(frozen=True)
class DriverSpec:
    """One driver: its executables, how its simulator is started, and what tools do with it.

    Values in ``sim_arguments`` and ``node_parameters`` may name the
    placeholders of :meth:`link_values`: ``{port}`` (a free TCP port on 127.0.0.1),
    ``{link}`` (a pseudo-terminal path), ``{workdir}`` (a private directory),
    ``{password}`` and ``{password_file}``. ``node_parameters`` connect the node to its
    simulator; every tool adds its own common ones (rates, presets file).
    """

    name: str                    # short key: `soak.py capture`, `bench/run.py capture`
    title: str                   # one line for people
    package: str
    node_executable: str
    node_name: str
    sim_executable: str
    node_class: str              # 'module:Class' of the node (its default joints, limits)
    description: str             # the URDF file in share/<package>/urdf/
    joints: tuple[str, ...]      # in the order the node is configured with
    move_goal: tuple[float, ...]  # a reachable goal for the first joints (rad/m)
    sim_arguments: tuple[str, ...] = ()
    node_parameters: Mapping[str, Any] = field(default_factory=dict)
    #: the simulator's arguments under the launch file's ``sim:=true``: it serves the address
    #: the package's simulator YAML (config/<package>_sim.yaml) connects to, so no
    #: placeholder here
    launch_sim_arguments: tuple[str, ...] = ()
    #: the LINK_ARGUMENTS the node declares (its launch file takes them as arguments)
    link_parameters: tuple[str, ...] = ()
    password: str = ''           # the simulator's device password (never logged)
    sim_handle: str = ''         # 'module:Class' of the in-process simulator handle
    #: 'module:function' returning the :class:`RefusedRequests` of the driver's own services
    #: (the property tests); '' when it has none
    refused_requests: str = ''
    #: 'module:function' of the driver's read-only probe (gimbal_probe,
    #: gimbal_driver_common.probe): link -> the attempts it makes there; '' = none
    probe: str = ''
    demo: DemoSettings = field(default_factory=DemoSettings)
    soak: SoakSettings = field(default_factory=SoakSettings)
    bench: BenchSettings = field(default_factory=BenchSettings)

    @property
    def namespace(self) -> str:
        """The namespace the demo runs the node in (node name without ``_driver``)."""
        return '/' + self.node_name.removesuffix('_driver')

    def link_values(self, workdir: Path, port: int = 0) -> dict[str, Any]:
        """The placeholder values for a simulator in ``workdir`` on ``port``."""
        return {'port': port, 'link': str(workdir / f'{self.name}_tty'),
                'workdir': str(workdir), 'password': self.password,
                'password_file': str(workdir / f'{self.name}_password')}

    def sim_argv(self, workdir: Path, port: int = 0) -> list[str]:
        values = self.link_values(workdir, port)
        return [argument.format(**values) for argument in self.sim_arguments]

    def parameters(self, workdir: Path, port: int = 0) -> dict[str, Any]:
        """``node_parameters`` with the placeholders filled; writes the password file (mode
        0600) the parameters name, so the password is never on a command line."""
        values = self.link_values(workdir, port)
        if self.password:
            password_file = values['password_file']
            descriptor = os.open(password_file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            os.fchmod(descriptor, 0o600)  # a file that existed keeps its mode otherwise
            with os.fdopen(descriptor, 'w', encoding='utf-8') as stream:
                stream.write(self.password + '\n')
        return {key: fill(value, values) for key, value in self.node_parameters.items()}

    @property
    def is_reference(self) -> bool:
        """The reference virtual gimbal (an invented device, no vendor document)."""
        return self.package == REFERENCE_PACKAGE

    def __post_init__(self) -> None:
        unknown = [name for name in self.link_parameters if name not in LINK_ARGUMENTS]
        if unknown:
            raise RegistryError(f'{self.name}: link_parameters {unknown} are not among '
                                f'{list(LINK_ARGUMENTS)}')

    def executables(self) -> tuple[str, str]:
        return self.node_executable, self.sim_executable


def fill(value: Any, values: Mapping[str, Any]) -> Any:
    """A parameter value with placeholders filled (strings, and strings in lists); a value
    that is one placeholder alone keeps the placeholder's type (``'{port}'`` -> an int)."""
    if isinstance(value, str):
        if value.startswith('{') and value.endswith('}') and value[1:-1] in values:
            return values[value[1:-1]]
        return value.format(**values)
    if isinstance(value, (list, tuple)):
        return [fill(item, values) for item in value]
    return value


def resolve(reference: str) -> Any:
    """The object a ``'module:attribute'`` reference names."""
    module, _, attribute = reference.partition(':')
    if not module or not attribute:
        raise RegistryError(f'{reference!r} is not a module:attribute reference')
    try:
        target: Any = importlib.import_module(module)
        for part in attribute.split('.'):
            target = getattr(target, part)
    except (ImportError, AttributeError) as exc:
        raise RegistryError(f'{reference!r} does not load: {exc}') from exc
    return target


def drivers() -> list[DriverSpec]:
    """Every registered driver, the reference virtual gimbal first, then by name.

    Raises :class:`RegistryError` for a registration that does not load or is not a
    :class:`DriverSpec`, and for two drivers with one name.
    """
    found: dict[str, DriverSpec] = {}
    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            spec = entry.load()
        except Exception as exc:  # any import error: name the registration that failed
            raise RegistryError(f'driver registration {entry.name} = {entry.value} does not '
                                f'load: {type(exc).__name__}: {exc}') from exc
        if not isinstance(spec, DriverSpec):
            raise RegistryError(f'driver registration {entry.name} = {entry.value} is a '
                                f'{type(spec).__name__}, not a DriverSpec')
        if spec.name != entry.name:
            raise RegistryError(f'driver registration {entry.name} names a spec called '
                                f'{spec.name!r}; the entry-point name must equal spec.name')
        other = found.get(spec.name)
        if other is not None and other != spec:
            raise RegistryError(f'two drivers are registered as {spec.name!r}: '
                                f'{other.package} and {spec.package}')
        found[spec.name] = spec
    return sorted(found.values(), key=lambda s: (not s.is_reference, s.name))


def driver_of_package(package: str) -> DriverSpec:
    """The registered driver of ``package`` (KeyError naming the registered packages)."""
    return _registered('package', package)


def driver(name: str) -> DriverSpec:
    """The registered driver ``name`` (KeyError naming the registered ones)."""
    return _registered('name', name)


def _registered(field_name: str, value: str) -> DriverSpec:
    specs = drivers()
    for spec in specs:
        if getattr(spec, field_name) == value:
            return spec
    raise KeyError(f'no driver with {field_name} {value!r} is registered; registered: '
                   f'{[getattr(s, field_name) for s in specs]}')



def parameter_arguments(parameters: Mapping[str, Any]) -> list[str]:
    """``-p name:=value`` command-line arguments for ``--ros-args``: floats keep their
    decimal point (double parameters), strings in lists are quoted (string arrays)."""
    arguments: list[str] = []
    for name, value in parameters.items():
        arguments += ['-p', f'{name}:={parameter_text(value)}']
    return arguments


def parameter_text(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(repr(v) if isinstance(v, (float, str)) else parameter_text(v)
                               for v in value) + ']'
    return str(value)
