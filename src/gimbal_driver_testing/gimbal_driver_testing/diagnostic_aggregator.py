"""diagnostic_aggregator's rules in Python, to check the analyzer files the drivers ship.

diagnostic_aggregator (C++, ros/diagnostics, branch ros2-jazzy) is not installable here, so
this module follows its sources step by step, each function naming what it follows:

- how the parameter file is read: the aggregator is a node named ``analyzers`` that
  declares every parameter of the file (``Aggregator::Aggregator``, aggregator.cpp); nested
  maps are dotted names, as rcl's YAML parser gives them;
- how analyzers are created: ``AnalyzerGroup::init`` (analyzer_group.cpp) walks the
  parameters in name order and makes an analyzer of each ``<ns>.type`` / ``<ns>.path``;
- how one GenericAnalyzer reads its parameters (``GenericAnalyzer::init``,
  generic_analyzer.cpp), matches a status (``GenericAnalyzer::match``), and reports
  (``GenericAnalyzerBase::report``, generic_analyzer_base.hpp, then
  ``GenericAnalyzer::report``): output names are the analyzer's path plus the status name
  (``StatusItem::toStatusMsg``, status_item.cpp; ``getOutputName``) with the prefixes
  removed (``removeLeadingNameChaff``, status_item.hpp); ``expected`` names are items from
  the start, STALE "Missing" until a status of that name arrives;
- what no analyzer claims goes to ``<base path>/Other`` (``OtherAnalyzer``,
  other_analyzer.hpp).

What the Jazzy sources do, and so this module too: ``name`` is not read (nothing fills the
list it would match), and ``expected`` only adds the placeholder items, it does not match:
a status is claimed by ``startswith``, ``contains`` (substring), ``regex`` (whole name) or
``find_and_remove_prefix``. A single string where a list is read, or an integer ``timeout``,
makes rclcpp throw: here :class:`AnalyzerConfigError`. Only GenericAnalyzer is modelled.
Times are plain seconds given by the caller (the aggregator uses its clock at arrival).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import yaml

GENERIC = 'diagnostic_aggregator/GenericAnalyzer'
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_TEXT = {OK: 'OK', WARN: 'Warning', ERROR: 'Error', STALE: 'Stale'}  # valToMsg
#: the GenericAnalyzer parameters that GenericAnalyzer::init reads (``type`` is the group's)
READ_KEYS = frozenset({'path', 'find_and_remove_prefix', 'remove_prefix', 'startswith',
                       'contains', 'expected', 'regex', 'timeout', 'num_items',
                       'discard_stale', 'type'})


class AnalyzerConfigError(ValueError):
    """What makes the aggregator throw, or leaves an analyzer uninitialized."""


@dataclass
class Status:
    """A diagnostic_msgs/DiagnosticStatus as the aggregator outputs it."""

    name: str
    level: int = OK
    message: str = ''
    hardware_id: str = ''
    values: list[tuple[str, str]] = field(default_factory=list)


def level_of(value: Any) -> int:
    """A DiagnosticStatus level (rclpy gives ``bytes``), mapped like ``valToLevel``."""
    level = value[0] if isinstance(value, (bytes, bytearray)) else int(value)
    return level if level in LEVEL_TEXT else ERROR


def output_name(item_name: str) -> str:
    """``getOutputName`` (status_item.hpp): every '/' becomes a space."""
    return item_name.replace('/', ' ')


def remove_leading_name_chaff(input_name: str, chaff: str) -> str:
    """``removeLeadingNameChaff`` (status_item.hpp): after the last '/', drop ``chaff`` if
    the name's first occurrence of it starts there, then a leading ':' and leading spaces."""
    name = input_name
    if not chaff:
        return name
    last_slash = name.rfind('/')
    start = name[:last_slash] + '/'
    if name.find(chaff) == last_slash + 1:
        name = name[:last_slash + 1] + name[last_slash + 1 + len(chaff):]
    if name.find(':', last_slash) == last_slash + 1:
        name = start + name[last_slash + 2:]
    while name.find(' ', last_slash) == last_slash + 1:
        name = start + name[last_slash + 2:]
    return name


@dataclass
class StatusItem:
    """``StatusItem`` (status_item.cpp): the newest status of one name and when it came."""

    name: str
    level: int
    message: str
    update_time: float
    hardware_id: str = ''
    values: list[tuple[str, str]] = field(default_factory=list)

    @classmethod
    def of(cls, status: Any, now: float) -> StatusItem:
        return cls(status.name, level_of(status.level), status.message, now,
                   status.hardware_id, [(kv.key, kv.value) for kv in status.values])

    def to_status(self, path: str, stale: bool) -> Status:
        """``StatusItem::toStatusMsg``."""
        name = '/' + output_name(self.name) if path == '/' else \
            f'{path}/{output_name(self.name)}'
        return Status(name, STALE if stale else self.level, self.message, self.hardware_id,
                      list(self.values))


def _string_array(key: str, value: Any) -> list[str]:
    """``Parameter::as_string_array``: anything but a list of strings throws."""
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise AnalyzerConfigError(f'{key}: {value!r} is not a string array (rclcpp throws '
                                  'ParameterTypeException on as_string_array)')
    return list(value)


class GenericAnalyzerBase:
    """``GenericAnalyzerBase`` (generic_analyzer_base.hpp): the items and their report."""

    def __init__(self, nice_name: str, base_path: str, timeout: float = -1.0,
                 num_items: int = -1, discard_stale: bool = False) -> None:
        self.nice_name = nice_name
        self.path = f'{base_path}/{nice_name}'   # GenericAnalyzerBase::init
        self.timeout = timeout
        self.num_items = num_items
        self.discard_stale = discard_stale and timeout > 0
        self.items: dict[str, StatusItem] = {}

    def analyze(self, item: StatusItem) -> bool:
        self.items[item.name] = item
        return True

    def report(self, now: float) -> list[Status]:
        header = Status(self.path, OK, 'OK')
        processed = [header]
        all_stale = True
        for name in sorted(self.items):   # std::map order
            item = self.items[name]
            stale = self.timeout > 0 and now - item.update_time > self.timeout
            if self.discard_stale and stale:
                del self.items[name]
                continue
            header.level = max(header.level, item.level)
            header.values.append((name, item.message))
            all_stale = all_stale and (item.level == STALE or stale)
            processed.append(item.to_status(self.path, stale))
            if stale:
                header.level = STALE
        if all_stale:
            header.level = OK if self.discard_stale else STALE
        elif header.level == STALE:
            header.level = ERROR
        header.message = LEVEL_TEXT[header.level]
        count = (len(self.items) + 128) % 256 - 128   # static_cast<int8_t>
        if self.num_items == 0 and not self.items:
            header.level, header.message = OK, 'OK'
        elif self.num_items > 0 and count != self.num_items:
            header.level = max(ERROR, header.level)
            header.message = (f'Expected {self.num_items}, found {len(self.items)}'
                              if self.items else f'No items found, expected {self.num_items}')
        return processed


class GenericAnalyzer(GenericAnalyzerBase):
    """``GenericAnalyzer`` (generic_analyzer.cpp)."""

    def __init__(self, breadcrumb: str, base_path: str, parameters: Mapping[str, Any],
                 now: float = 0.0) -> None:
        """``GenericAnalyzer::init``: the parameters under ``breadcrumb``, in name order."""
        nice_name, timeout, num_items, discard_stale = breadcrumb, 5.0, -1, False
        self.chaff: list[str] = []
        self.startswith: list[str] = []
        self.contains: list[str] = []
        self.regex: list[re.Pattern[str]] = []
        expected: list[str] = []
        #: keys GenericAnalyzer::init does not read (``name`` among them): silently ignored
        self.ignored = sorted(set(parameters) - READ_KEYS)
        for key in sorted(parameters):
            value = parameters[key]
            if key == 'path':
                if not isinstance(value, str):
                    raise AnalyzerConfigError(f'{breadcrumb}.path: {value!r} is not a string')
                nice_name = value
            elif key == 'find_and_remove_prefix':
                self.chaff = self.startswith = _string_array(key, value)
            elif key == 'remove_prefix':
                self.chaff = _string_array(key, value)
            elif key == 'startswith':
                self.startswith = _string_array(key, value)
            elif key == 'contains':
                self.contains = _string_array(key, value)
            elif key == 'expected':
                expected = _string_array(key, value)
            elif key == 'regex':
                for pattern in _string_array(key, value):
                    try:   # std::regex (ECMAScript); a bad one is logged and left out
                        self.regex.append(re.compile(pattern))
                    except re.error:
                        continue
            elif key == 'timeout':
                if not isinstance(value, float):
                    raise AnalyzerConfigError(f'{breadcrumb}.timeout: {value!r} is not a '
                                              'double (as_double throws; write 5.0)')
                timeout = value
            elif key == 'num_items':
                if isinstance(value, bool) or not isinstance(value, int):
                    raise AnalyzerConfigError(f'{breadcrumb}.num_items: {value!r} is not an '
                                              'integer')
                num_items = value
            elif key == 'discard_stale':
                if not isinstance(value, bool):
                    raise AnalyzerConfigError(f'{breadcrumb}.discard_stale: {value!r} is not '
                                              'a bool')
                discard_stale = value
        if not (self.startswith or self.contains or self.regex):
            raise AnalyzerConfigError(f'GenericAnalyzer {nice_name!r} was not initialized with '
                                      'any way of checking diagnostics (startswith, contains, '
                                      'regex or find_and_remove_prefix; name and expected '
                                      'match nothing)')
        self.chaff = [output_name(chaff) for chaff in self.chaff]
        super().__init__(nice_name, base_path, timeout, num_items, discard_stale)
        self.expected = expected
        for name in expected:   # addItem: STALE "Missing" until a status of that name
            self.items[name] = StatusItem(name, STALE, 'Missing', now)

    def match(self, name: str) -> bool:
        """``GenericAnalyzer::match``: regex (whole name), startswith, contains."""
        return (any(pattern.fullmatch(name) for pattern in self.regex)
                or any(name.startswith(prefix) for prefix in self.startswith)
                or any(part in name for part in self.contains))

    def report(self, now: float) -> list[Status]:
        """``GenericAnalyzer::report``: the base report with the prefixes removed from every
        name (its check of missing expected names reads a list that init never fills)."""
        processed = super().report(now)
        for status in processed:
            for chaff in self.chaff:
                status.name = remove_leading_name_chaff(status.name, chaff)
        return processed


def node_parameters(document: Mapping[str, Any], node: str = '/analyzers') -> dict[str, Any]:
    """The parameters a node of fully qualified name ``node`` takes from a parameter file:
    the entries keyed ``/**``, ``/**/<name>`` or its name, ``ros__parameters`` flattened
    to dotted names (later entries win, as rcl applies them)."""
    name = node.rsplit('/', 1)[-1]
    parameters: dict[str, Any] = {}
    for key, entry in document.items():
        full = key if key.startswith('/') else '/' + key
        if full in ('/**', f'/**/{name}', node):
            parameters.update(_flatten(entry.get('ros__parameters', {})))
    return parameters


def _flatten(tree: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f'{prefix}{key}.'))
        else:
            flat[f'{prefix}{key}'] = value
    return flat


class Aggregator:
    """``Aggregator`` with its top ``AnalyzerGroup`` and ``OtherAnalyzer``."""

    def __init__(self, parameters: Mapping[str, Any], now: float = 0.0) -> None:
        path = parameters.get('path', '')
        self.base_path = f'/{path}' if path else ''   # Aggregator::Aggregator
        self.analyzers: dict[str, GenericAnalyzer] = {}
        ns = an_type = an_path = ''
        for key in sorted(parameters):   # AnalyzerGroup::init, breadcrumb ""
            position = 10 if key.startswith('analyzers.') else 0
            ns = key.split('.', 1)[0] if position == 0 else \
                key[:key.find('.', position)] if key.find('.', position) >= 0 else key
            if key == f'{ns}.type':
                an_type = str(parameters[key])
            if key == f'{ns}.path':
                an_path = str(parameters[key])
            if ns and an_type and an_path:
                if an_type != GENERIC:
                    raise AnalyzerConfigError(f'{ns}: type {an_type!r} is not modelled here')
                prefix = f'{ns}.'
                mine = {k[len(prefix):]: v for k, v in parameters.items()
                        if k.startswith(prefix)}
                self.analyzers[ns] = GenericAnalyzer(ns, self.base_path, mine, now)
                ns = an_type = an_path = ''
        self.other = GenericAnalyzerBase('Other', self.base_path, 5.0, -1, True)

    @classmethod
    def from_yaml(cls, text: str, node: str = '/analyzers', now: float = 0.0) -> Aggregator:
        return cls(node_parameters(yaml.safe_load(text) or {}, node), now)

    def claimed_by(self, name: str) -> list[str]:
        """The analyzers (their parameter namespaces) that match a status name."""
        return [ns for ns, analyzer in self.analyzers.items() if analyzer.match(name)]

    def feed(self, statuses: Iterable[Any], now: float) -> None:
        """``Aggregator::diagCallback``: each status to every analyzer that matches it,
        to Other when none does."""
        for status in statuses:
            item = StatusItem.of(status, now)
            claimed = [self.analyzers[ns] for ns in self.claimed_by(item.name)]
            for analyzer in claimed:
                analyzer.analyze(item)
            if not claimed:
                self.other.analyze(item)

    def report(self, now: float) -> list[Status]:
        """``Aggregator::publishData``: the group's report (``AnalyzerGroup::report``: each
        analyzer's, then a header when there is a base path), then Other's, if it has any."""
        output: list[Status] = []
        header = Status(self.base_path, OK, 'OK')
        all_stale = True
        for analyzer in self.analyzers.values():
            for status in analyzer.report(now):
                output.append(status)
                if status.name == analyzer.path:
                    header.values.append((analyzer.nice_name, status.message))
                    all_stale = all_stale and status.level == STALE
                    header.level = max(header.level, status.level)
        if header.level == STALE and not all_stale:
            header.level = ERROR
        header.message = LEVEL_TEXT[header.level]
        if self.base_path not in ('', '/'):
            output.append(header)
        other = self.other.report(now)
        return output + (other if len(other) > 1 else [])
