"""Parameter declaration with descriptors and ranges, and clear start-up errors.

Every declared parameter is also registered in a :class:`ParameterRegistry`
with how it may change while the node runs:

* ``Change.RUNTIME``: checked like at start-up, then applied at once by the
  driver's apply function (and, where the device holds the setting, sent to it);
* ``Change.READ_ONLY``: refused (rclpy refuses it from the descriptor);
* ``Change.RECONFIGURE`` (the default): refused with "needs reconfigure",
  because the value is only read when the node starts or the link opens.

One validation path: :func:`check_value` (element ranges, choices) and the
registered cross-parameter checks run both at start-up and for every
``ros2 param set``; rclpy's descriptor checks (type, scalar range, read-only)
apply to both as well.

A set is all or nothing: every check runs before any value is sent to the device, and
when the device refuses one value of a set, the values of the same set it had already
taken are sent back to their old values (:func:`send_all_or_nothing`).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.node import Node
from rclpy.parameter import Parameter


class ParameterError(ValueError):
    """A parameter value was refused; the message names the parameter."""


_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
}


def _array_type(default: Sequence[Any], element: type | None) -> int:
    kind = element or (type(default[0]) if default else float)
    return {
        bool: ParameterType.PARAMETER_BOOL_ARRAY,
        int: ParameterType.PARAMETER_INTEGER_ARRAY,
        float: ParameterType.PARAMETER_DOUBLE_ARRAY,
        str: ParameterType.PARAMETER_STRING_ARRAY,
    }[kind]


class Change(enum.Enum):
    """How a parameter may change while the node runs."""

    RUNTIME = 'runtime'
    READ_ONLY = 'read-only'
    RECONFIGURE = 'needs reconfigure'


#: what a value check gets to look up other parameters' values (the proposed ones on a set)
ValueOf = Callable[[str], Any]


@dataclass
class ParameterSpec:
    """A declared parameter: its value checks and how it may change at run time."""

    name: str
    value_range: tuple[float, float] | None = None
    choices: Sequence[str] | None = None
    change: Change = Change.RECONFIGURE
    #: stores the new value in the node (runs after rclpy accepted it; must not fail)
    apply: Callable[[Any], None] | None = None
    #: sends a value to the device; runs after every check, an exception refuses the set
    #: (and the set's values the device already took are sent again with their old values)
    send: Callable[[Any], None] | None = None
    #: why the value cannot change right now (e.g. an axis is moving), or None
    busy: Callable[[], str | None] | None = None


def plain_value(value: Any) -> Any:
    """Arrays as lists (rclpy hands out array.array or tuples for array parameters)."""
    if isinstance(value, str | bytes) or not isinstance(value, Iterable):
        return value
    return list(value)


def check_value(spec: ParameterSpec, value: Any) -> Any:
    """The checks rclpy's descriptor cannot express: array element ranges and choices."""
    value = plain_value(value)
    if spec.value_range is not None:
        low, high = spec.value_range
        for item in value if isinstance(value, list) else [value]:
            if not low <= item <= high:
                what = 'element ' if isinstance(value, list) else ''
                raise ParameterError(
                    f'parameter {spec.name!r}: {what}{item} outside [{low}, {high}]'
                )
    if spec.choices is not None and value not in spec.choices:
        raise ParameterError(
            f'parameter {spec.name!r}: {value!r} is not one of {list(spec.choices)}'
        )
    return value


@dataclass(frozen=True)
class DeviceChange:
    """One device-held value of a parameter set: how to send it, the new and the old value."""

    name: str
    send: Callable[[Any], None]
    value: Any
    previous: Any


def send_all_or_nothing(changes: Sequence[DeviceChange]) -> str | None:
    """Send each change in turn; None when the device took them all.

    When the device refuses one, the changes it had already taken get their previous
    values back, in reverse order, and the reason for the refusal is returned (naming any
    value that could not be put back, so the operator knows what the device now holds).
    """
    taken: list[DeviceChange] = []
    for change in changes:
        try:
            change.send(change.value)
        except Exception as exc:  # noqa: BLE001 - the device's refusal becomes the reason
            reason = f'parameter {change.name!r}: the device refused {change.value!r}: {exc}'
            break
        taken.append(change)
    else:
        return None
    not_restored = []
    for change in reversed(taken):
        try:
            change.send(change.previous)
        except Exception as exc:  # noqa: BLE001 - reported with the refusal
            not_restored.append(f'{change.name!r} may still hold {change.value!r} '
                                f'(putting back {change.previous!r} failed: {exc})')
    if not_restored:
        reason += '; ' + '; '.join(not_restored)
    return reason


@dataclass
class _GroupCheck:
    names: frozenset[str]
    check: Callable[[ValueOf], object]


@dataclass
class ParameterRegistry:
    """Which parameters a node declared and how each may change at run time.

    :meth:`attach` hooks it into rclpy: the on-set callback validates (and
    refuses read-only / needs-reconfigure ones with the reason), the post-set
    callback applies the accepted values.
    """

    node: Node
    specs: dict[str, ParameterSpec] = field(default_factory=dict)
    checks: list[_GroupCheck] = field(default_factory=list)

    def add(self, spec: ParameterSpec) -> None:
        self.specs[spec.name] = spec

    def make_runtime(
        self, name: str, apply: Callable[[Any], None],
        send: Callable[[Any], None] | None = None,
        busy: Callable[[], str | None] | None = None,
        check: Callable[[Any], object] | None = None,
    ) -> None:
        """Mark a declared parameter as applicable at run time.

        ``check(value)`` is an extra per-value check that must be the same one the
        driver runs at start-up (it raises :class:`ParameterError`).
        """
        spec = self.specs[name]
        if spec.change is Change.READ_ONLY:
            raise ValueError(f'parameter {name!r} is read-only; it cannot be runtime')
        spec.change, spec.apply, spec.send, spec.busy = Change.RUNTIME, apply, send, busy
        if check is not None:
            self.add_check([name], lambda value_of: check(value_of(name)))

    def add_check(self, names: Iterable[str], check: Callable[[ValueOf], object]) -> None:
        """A check over several parameters, run at start-up and whenever one of them is set."""
        self.checks.append(_GroupCheck(frozenset(names), check))

    def check_all(self) -> None:
        """Run every registered check on the current values (start-up)."""
        for group in self.checks:
            self._run(group, self.current)

    def attach(self) -> None:
        self.node.add_on_set_parameters_callback(self._on_set)
        self.node.add_post_set_parameters_callback(self._after_set)

    def current(self, name: str) -> Any:
        """The value ``name`` has now."""
        return plain_value(self.node.get_parameter(name).value)

    @staticmethod
    def _run(group: _GroupCheck, value_of: ValueOf) -> None:
        try:
            group.check(value_of)
        except ParameterError:
            raise
        except ValueError as exc:
            raise ParameterError(f'parameter {"/".join(sorted(group.names))}: {exc}') from exc

    def refusal(self, parameters: Sequence[Parameter]) -> str | None:
        """Why this set must be refused, or None; sends device-held values when it is not.

        Every check runs first; only then are the device-held values sent, all or nothing.
        """
        proposed = {p.name: plain_value(p.value) for p in parameters}
        touched = [self.specs[p.name] for p in parameters if p.name in self.specs]
        for spec in touched:
            if spec.change is Change.READ_ONLY:
                return f'parameter {spec.name!r} is read-only'
            if spec.change is Change.RECONFIGURE:
                return (f'parameter {spec.name!r} needs reconfigure: it is read only when '
                        'the node starts and opens the device link; restart the node with '
                        'the new value')
        try:
            for spec in touched:
                check_value(spec, proposed[spec.name])
            for group in self.checks:
                if group.names & proposed.keys():
                    self._run(group, lambda n: proposed[n] if n in proposed else self.current(n))
        except ParameterError as exc:
            return str(exc)
        for spec in touched:
            reason = spec.busy() if spec.busy else None
            if reason:
                return f'parameter {spec.name!r} cannot change now: {reason}'
        return send_all_or_nothing([
            DeviceChange(spec.name, spec.send, proposed[spec.name], self.current(spec.name))
            for spec in touched if spec.send is not None])

    def _on_set(self, parameters: list[Parameter]) -> SetParametersResult:
        reason = self.refusal(parameters)
        if reason:
            self.node.get_logger().warning(f'parameter change refused: {reason}')
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _after_set(self, parameters: list[Parameter]) -> None:
        for parameter in parameters:
            spec = self.specs.get(parameter.name)
            if spec is None or spec.apply is None:
                continue
            try:
                spec.apply(plain_value(parameter.value))
            except Exception as exc:  # noqa: BLE001 - never let a post-set raise into rclpy
                self.node.get_logger().error(f'applying parameter {parameter.name!r} '
                                             f'failed: {exc}')
                continue
            self.node.get_logger().info(f'parameter {parameter.name!r} set to '
                                        f'{plain_value(parameter.value)!r}')


def _declare_empty_array(node: Node, name: str, descriptor: ParameterDescriptor) -> Any:
    """An array parameter whose default is empty ("unknown", e.g. site_position).

    rclpy infers a type from the default, and an empty list reads as a byte array
    (``Parameter.Type.from_parameter_value([])``), which then refuses ``[1.0, 2.0]``; so
    it is declared by its type, and set to an empty array of that type when no override
    gave a value (``-p name:=[]`` leaves it unset too: rcl cannot type an empty list).
    """
    kind = Parameter.Type(descriptor.type)
    value = node.declare_parameter(name, kind, descriptor).value
    if value is None:
        node.set_parameters([Parameter(name, kind, [])])
        value = []
    return value


def declare(
    node: Node,
    name: str,
    default: Any,
    description: str,
    value_range: tuple[float, float] | None = None,
    element_type: type | None = None,
    read_only: bool = False,
    choices: Sequence[str] | None = None,
    registry: ParameterRegistry | None = None,
    ignore_override: bool = False,
) -> Any:
    """Declare ``name`` with a descriptor and return its (checked) value.

    ``value_range`` applies to numbers and to every element of numeric arrays;
    ``choices`` restricts strings. Violations raise :class:`ParameterError`.
    ``ignore_override``: declare ``default`` whatever the command line gave (a secret
    taken with :func:`take_secret` is declared redacted this way).
    The parameter is registered in ``registry`` (default: the node's
    ``parameter_registry``, if it has one) as read-only, or as needing a
    reconfigure until the driver marks it runtime.
    """
    is_array = isinstance(default, list | tuple)
    descriptor = ParameterDescriptor(
        name=name,
        description=description + (f' (one of {list(choices)})' if choices else ''),
        read_only=read_only,
        type=_array_type(default, element_type) if is_array else _TYPES[type(default)],
    )
    if value_range is not None and not is_array:
        low, high = value_range
        if isinstance(default, int) and not isinstance(default, bool):
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high))]
        else:
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(low), to_value=float(high))
            ]
    try:
        if is_array and not default:
            value = _declare_empty_array(node, name, descriptor)
        else:
            value = node.declare_parameter(name, default, descriptor,
                                           ignore_override=ignore_override).value
    except Exception as exc:  # rclpy raises several types for bad overrides
        raise ParameterError(f'parameter {name!r}: {exc}') from exc
    if is_array and value is None:
        value = []
    spec = ParameterSpec(
        name, value_range, choices, Change.READ_ONLY if read_only else Change.RECONFIGURE
    )
    value = check_value(spec, value)
    registry = registry or getattr(node, 'parameter_registry', None)
    if registry is not None:
        registry.add(spec)
    return value


def take_secret(node: Node, name: str) -> Parameter | None:
    """The value the command line or a parameters file gave ``name``, without declaring it
    (a declared value goes out on /parameter_events); None when none was given.

    Public rclpy only: ``name`` is declared once under an on-set callback that records the
    value and refuses it, so nothing is set and nothing is published. The refusal's
    exception carries the value: it is dropped here, never logged.
    """
    taken: list[Parameter] = []

    def capture(parameters: list[Parameter]) -> SetParametersResult:
        taken.extend(p for p in parameters if p.name == name)
        return SetParametersResult(successful=not taken, reason='taken, not set')

    node.add_on_set_parameters_callback(capture)
    try:
        node.declare_parameter(name, None, ParameterDescriptor(dynamic_typing=True))
    except Exception:  # noqa: BLE001 - the refusal above; its text holds the secret
        pass
    finally:
        node.remove_on_set_parameters_callback(capture)
    if node.has_parameter(name):
        node.undeclare_parameter(name)
    if not taken or taken[0].type_ == Parameter.Type.NOT_SET:
        return None
    return taken[0]
