"""The users' reference cannot drift from the nodes.

For every registered driver the node runs against its simulator (the registry's in-process
``SimHandle``, as the crash-safety test starts it), and what it really offers (its
publishers, subscriptions, services and action servers, from the ROS graph, and its
parameters with their types, from ``list_parameters``/``describe_parameters``) is compared
with what the reference lists, both ways: the common tables of ``docs/interface.md`` plus
the tables of the driver's manual (``src/<package>/README.md``).

The reference tables have a fixed layout (``reference_tables`` reads it): a markdown table
whose header starts with ``topic``, ``service``, ``action``, ``service / action`` or
``parameter`` lists one interface per row; its first cell is the name in backticks (``~/name``
= the node's private namespace, ``/name`` = absolute, else relative to the node's namespace;
several names may share a row, ``a``, ``b``), its second the type in backticks, one for the
row or one per name (a ROS type such as
``sensor_msgs/msg/JointState``, or a parameter type: ``bool``, ``integer``, ``double``,
``string``, ``bool[]``, ``integer[]``, ``double[]``, ``string[]``, ``byte[]``); a topic
table's third cell is ``pub`` or ``sub``.

Run ``python tests/test_reference.py <driver>`` (a registry name, e.g. ``capture``) to print
what the node offers in that layout.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import pytest
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, ListParameters
from rclpy.action import get_action_server_names_and_types_by_node
from sensor_msgs.msg import JointState

from gimbal_driver_common.registry import DriverSpec, drivers
from gimbal_driver_common.sim_handle import make_handle
from gimbal_driver_testing import DomainLease, ManagedProcess, wait_for
from gimbal_driver_testing.ros import RosTestClient

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parent.parent
COMMON_REFERENCE = ROOT / 'docs' / 'interface.md'

#: What every rclpy lifecycle node offers by itself (ROS infrastructure, not the driver's
#: interface): the parameter and lifecycle services, /rosout, /parameter_events and the
#: lifecycle transition events. The reference names them once in prose.
ROS_INFRASTRUCTURE = {
    'service': {f'~/{name}' for name in (
        'describe_parameters', 'get_parameter_types', 'get_parameters',
        'get_type_description', 'list_parameters', 'set_parameters',
        'set_parameters_atomically', 'change_state', 'get_available_states',
        'get_available_transitions', 'get_state', 'get_transition_graph')},
    'pub': {'/rosout', '/parameter_events', '~/transition_event'},
    'sub': {'/parameter_events'},
    'parameter': {'use_sim_time', 'start_type_description_service'},
}

#: rcl_interfaces ParameterType -> the reference's name
PARAMETER_TYPES = {
    ParameterType.PARAMETER_BOOL: 'bool', ParameterType.PARAMETER_INTEGER: 'integer',
    ParameterType.PARAMETER_DOUBLE: 'double', ParameterType.PARAMETER_STRING: 'string',
    ParameterType.PARAMETER_BYTE_ARRAY: 'byte[]',
    ParameterType.PARAMETER_BOOL_ARRAY: 'bool[]',
    ParameterType.PARAMETER_INTEGER_ARRAY: 'integer[]',
    ParameterType.PARAMETER_DOUBLE_ARRAY: 'double[]',
    ParameterType.PARAMETER_STRING_ARRAY: 'string[]',
}

TABLE_KINDS = ('topic', 'service', 'action', 'service / action', 'parameter')
_CODE = re.compile(r'`([^`]+)`')


def split_row(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip('|').split('|')]


def reference_tables(text: str) -> Iterator[tuple[str, list[str]]]:
    """(kind, cells) for every row of every interface table in a markdown text."""
    kind = None
    for line in text.splitlines():
        if not line.lstrip().startswith('|'):
            kind = None
            continue
        cells = split_row(line)
        if kind is None:
            kind = cells[0] if cells[0] in TABLE_KINDS else ''
            continue
        if kind and not set(cells[0]) <= set('-: '):
            yield kind, cells


def reference_entries(text: str) -> dict[tuple[str, str], str]:
    """(kind, name) -> type, kind being pub/sub/service/action/parameter."""
    entries: dict[tuple[str, str], str] = {}
    for kind, cells in reference_tables(text):
        names = _CODE.findall(cells[0])
        types = _CODE.findall(cells[1]) if len(cells) > 1 else []
        assert names and len(types) in (1, len(names)), \
            f'a {kind} row without a name, or not one type (or one per name): {cells}'
        if kind == 'topic':
            direction = cells[2] if len(cells) > 2 else ''
            assert direction in ('pub', 'sub'), f'topic {names}: direction {direction!r}'
            kind = direction
        for name, type_name in zip(names, types * len(names) if len(types) == 1 else types,
                                   strict=True):
            row_kind = kind
            if kind == 'service / action':
                row_kind = 'action' if '/action/' in type_name else 'service'
            entries[(row_kind, name)] = type_name
    return entries


def driver_manual(spec: DriverSpec) -> Path:
    return ROOT / 'src' / spec.package / 'README.md'


def documented(spec: DriverSpec) -> dict[tuple[str, str], str]:
    common = reference_entries(COMMON_REFERENCE.read_text())
    extras = reference_entries(driver_manual(spec).read_text())
    # a manual may say more about a common entry, but not give it another type
    clash = {key for key in set(common) & set(extras) if common[key] != extras[key]}
    assert not clash, f'{driver_manual(spec)} gives common entries other types: {clash}'
    return {**common, **extras}


def private(name: str, node_name: str) -> str:
    """A graph name as the reference writes it: the node's private names as ``~/x``."""
    prefix = f'/{node_name}/'
    if name.startswith(prefix):
        return '~/' + name[len(prefix):]
    if name.count('/') == 1 and name not in ('/rosout', '/parameter_events', '/diagnostics'):
        return name[1:]  # relative to the (root) namespace
    return name


def ros_type(types: list[str]) -> str:
    assert len(types) == 1, types
    return types[0]


def offered(ros: RosTestClient, node_name: str) -> dict[tuple[str, str], str]:
    """What the node offers, read from the graph and its parameter services."""
    node = ros.node
    found: dict[tuple[str, str], str] = {}
    for kind, query in (('pub', node.get_publisher_names_and_types_by_node),
                        ('sub', node.get_subscriber_names_and_types_by_node),
                        ('service', node.get_service_names_and_types_by_node)):
        for name, types in query(node_name, '/'):
            found[(kind, private(name, node_name))] = ros_type(types)
    for name, types in get_action_server_names_and_types_by_node(node, node_name, '/'):
        found[('action', private(name, node_name))] = ros_type(types)
    # an action's own services and topics are the action's, not separate interfaces
    actions = [name for kind, name in found if kind == 'action']
    for key in list(found):
        if any(key[1].startswith(f'{action}/_action/') for action in actions):
            del found[key]
    names = ros.call(ListParameters, f'/{node_name}/list_parameters',
                     ListParameters.Request(), timeout=30).result.names
    described = ros.call(DescribeParameters, f'/{node_name}/describe_parameters',
                         DescribeParameters.Request(names=names), timeout=30).descriptors
    for descriptor in described:
        found[('parameter', descriptor.name)] = PARAMETER_TYPES.get(
            descriptor.type, f'type {descriptor.type}')
    return {key: value for key, value in found.items()
            if key[1] not in ROS_INFRASTRUCTURE.get(key[0], set())}


@contextmanager
def running_node(spec: DriverSpec, workdir: Path) -> Iterator[RosTestClient]:
    """The driver's node against its in-process simulator, active and publishing."""
    device = make_handle(spec, workdir, process_tests=True)
    device.start()
    try:
        with DomainLease() as domain, RosTestClient(domain, 'reference_check') as ros:
            params = [*device.link_parameters(), f'presets_file:={workdir / "presets.yaml"}']
            node = ManagedProcess.ros(spec.package, spec.node_executable, domain,
                                      ['--ros-args', *[x for p in params for x in ('-p', p)]])
            try:
                ros.wait_for_message('/joint_states', JointState, timeout=60)
                yield ros
            finally:
                node.stop()
    finally:
        device.stop()


def drift(spec: DriverSpec, ros: RosTestClient) -> tuple[dict, dict, dict]:
    """(undocumented, missing, wrong type) between the node and the reference."""
    listed = documented(spec)
    comparable = set(listed)

    def compare() -> dict[tuple[str, str], str]:
        if (spec.node_name, '/') not in ros.node.get_node_names_and_namespaces():
            return {}  # the graph has not seen the node yet
        return offered(ros, spec.node_name)

    # the graph fills in as discovery goes on: wait until everything listed is seen
    # (or give up and report what is missing)
    state = {'offered': compare()}

    def complete() -> bool:
        state['offered'] = compare()
        return comparable <= set(state['offered'])

    with suppress(TimeoutError):
        wait_for(complete, 20.0, 'the node to offer what the reference lists', 0.5)
    found = state['offered']
    undocumented = {key: found[key] for key in set(found) - set(listed)}
    missing = {key: listed[key] for key in comparable - set(found)}
    wrong = {key: (listed[key], found[key]) for key in set(found) & set(listed)
             if listed[key] != found[key]}
    return undocumented, missing, wrong


@pytest.mark.parametrize('spec', [spec for spec in drivers() if spec.sim_handle],
                         ids=lambda spec: spec.name)
def test_the_reference_lists_what_the_node_offers(spec: DriverSpec, tmp_path: Path) -> None:
    with running_node(spec, tmp_path) as ros:
        undocumented, missing, wrong = drift(spec, ros)
    where = f'docs/interface.md or src/{spec.package}/README.md'
    assert not undocumented, f'{spec.node_name} offers what {where} does not list: ' + \
        ', '.join(f'{k} {n} ({t})' for (k, n), t in sorted(undocumented.items()))
    assert not missing, f'{where} lists what {spec.node_name} does not offer: ' + \
        ', '.join(f'{k} {n} ({t})' for (k, n), t in sorted(missing.items()))
    assert not wrong, f'{where}: wrong types (listed, offered): {sorted(wrong.items())}'


def test_the_reference_tables_parse() -> None:
    """The layout rules hold, so a broken table is an error, not a silent gap."""
    text = """
| topic | type | direction | notes |
|---|---|---|---|
| `joint_states` | `sensor_msgs/msg/JointState` | pub | x |
| `~/a`, `~/b` | `std_msgs/msg/Float64` | sub | y |

| parameter | type | default | meaning |
|---|---|---|---|
| `publish_rate` | `double` | 50.0 | Hz |

| argument | default |
|---|---|
| `sim` | false |
"""
    assert reference_entries(text) == {
        ('pub', 'joint_states'): 'sensor_msgs/msg/JointState',
        ('sub', '~/a'): 'std_msgs/msg/Float64', ('sub', '~/b'): 'std_msgs/msg/Float64',
        ('parameter', 'publish_rate'): 'double'}
    with pytest.raises(AssertionError, match='direction'):
        reference_entries('| topic | type | direction |\n|---|---|---|\n| `x` | `t` | both |')
    for spec in drivers():
        assert documented(spec)


if __name__ == '__main__':
    import tempfile

    wanted = {spec.name: spec for spec in drivers()}[sys.argv[1]]
    with tempfile.TemporaryDirectory() as workdir, running_node(wanted, Path(workdir)) as ros:
        wait_for(lambda: ('parameter', 'publish_rate') in offered(ros, wanted.node_name), 20,
                 'parameters')
        import time
        time.sleep(3)  # a dump for writing the tables: let discovery settle
        for (kind, name), type_name in sorted(offered(ros, wanted.node_name).items()):
            print(f'{kind}\t{name}\t{type_name}')
