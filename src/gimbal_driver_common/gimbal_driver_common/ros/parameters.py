"""Parameter declaration with descriptors and ranges, and clear start-up errors."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.node import Node


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


def declare(
    node: Node,
    name: str,
    default: Any,
    description: str,
    value_range: tuple[float, float] | None = None,
    element_type: type | None = None,
    read_only: bool = False,
    choices: Sequence[str] | None = None,
) -> Any:
    """Declare ``name`` with a descriptor and return its (checked) value.

    ``value_range`` applies to numbers and to every element of numeric arrays;
    ``choices`` restricts strings. Violations raise :class:`ParameterError`.
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
        value = node.declare_parameter(name, default, descriptor).value
    except Exception as exc:  # rclpy raises several types for bad overrides
        raise ParameterError(f'parameter {name!r}: {exc}') from exc
    if is_array:
        value = list(value) if value is not None else []
        if value_range is not None:
            low, high = value_range
            for item in value:
                if not low <= item <= high:
                    raise ParameterError(
                        f'parameter {name!r}: element {item} outside [{low}, {high}]'
                    )
    if choices is not None and value not in choices:
        raise ParameterError(f'parameter {name!r}: {value!r} is not one of {list(choices)}')
    return value
