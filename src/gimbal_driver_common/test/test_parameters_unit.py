"""ParameterRegistry in-process: how a set is validated, refused, sent and applied.

The process-level tests (test_runtime_parameters.py and each driver's) show the
effects through the parameter services; these pin the rules on a plain rclpy node.
"""

from __future__ import annotations

import pytest
import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from gimbal_driver_common.ros.parameters import (
    Change,
    ParameterError,
    ParameterRegistry,
    declare,
    take_secret,
)
from gimbal_driver_testing import DomainLease

pytestmark = pytest.mark.ros


class Device:
    """Stands in for a device setting: records what was sent, can refuse."""

    def __init__(self) -> None:
        self.sent: list[object] = []
        self.refuse = ''

    def send(self, value: object) -> None:
        if self.refuse:
            raise RuntimeError(self.refuse)
        self.sent.append(value)


@pytest.fixture
def node():
    with DomainLease() as domain:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        node = Node('registry_test', context=context)
        try:
            yield node
        finally:
            node.destroy_node()
            rclpy.shutdown(context=context)


@pytest.fixture
def rig(node):
    registry = ParameterRegistry(node)
    applied: dict[str, object] = {}
    device = Device()
    busy: list[str] = []

    def param(name, default, **kwargs):
        return declare(node, name, default, name, registry=registry, **kwargs)

    param('rate', 10.0, value_range=(1.0, 100.0))
    param('scales', [1.0, 1.0], value_range=(-10.0, 10.0))
    param('mode', 'a', choices=('a', 'b'))
    param('low', 0.0)
    param('high', 1.0)
    param('names', ['x'], element_type=str, read_only=True)
    param('host', 'localhost')
    for name in ('scales', 'mode', 'low', 'high'):
        registry.make_runtime(name, lambda v, n=name: applied.__setitem__(n, v))
    registry.make_runtime('rate', lambda v: applied.__setitem__('rate', v), send=device.send,
                          busy=lambda: busy[0] if busy else None)

    def ordered(value_of) -> None:
        if value_of('low') > value_of('high'):
            raise ValueError(f"low {value_of('low')} above high {value_of('high')}")

    registry.add_check(['low', 'high'], ordered)
    registry.check_all()
    registry.attach()
    return node, registry, applied, device, busy


def set_one(node: Node, name: str, value: object):
    return node.set_parameters([Parameter(name, value=value)])[0]


def test_a_runtime_parameter_is_sent_then_applied(rig) -> None:
    node, _, applied, device, _ = rig
    result = set_one(node, 'rate', 20.0)
    assert result.successful, result.reason
    assert device.sent == [20.0] and applied['rate'] == 20.0
    assert node.get_parameter('rate').value == 20.0


def test_a_device_refusal_refuses_the_set_and_nothing_is_applied(rig) -> None:
    node, _, applied, device, _ = rig
    device.refuse = 'NACK 3'
    result = set_one(node, 'rate', 30.0)
    assert not result.successful
    assert "'rate'" in result.reason and 'NACK 3' in result.reason and '30.0' in result.reason
    assert 'rate' not in applied and node.get_parameter('rate').value == 10.0


class HeldValues:
    """Two device-held values (like a rate and an interval list): logs sends, can refuse."""

    def __init__(self) -> None:
        self.held = {'interval': 1.0, 'limit': 5}
        self.log: list[tuple[str, object]] = []
        self.refused: set[tuple[str, object]] = set()

    def sender(self, name: str):
        def send(value: object) -> None:
            self.log.append((name, value))
            if (name, value) in self.refused:
                raise RuntimeError(f'NACK {name}')
            self.held[name] = value
        return send


@pytest.fixture
def two_held(node):
    registry = ParameterRegistry(node)
    device = HeldValues()
    applied: dict[str, object] = {}
    for name, value in device.held.items():
        declare(node, name, value, name, registry=registry)
        registry.make_runtime(name, lambda v, n=name: applied.__setitem__(n, v),
                              send=device.sender(name))
    declare(node, 'mode', 'a', 'mode', choices=('a', 'b'), registry=registry)
    registry.make_runtime('mode', lambda v: applied.__setitem__('mode', v))
    registry.attach()
    return node, device, applied


def test_a_refused_second_value_puts_the_first_back_on_the_device(two_held) -> None:
    node, device, applied = two_held
    device.refused.add(('limit', 9))
    result = node.set_parameters_atomically([Parameter('interval', value=2.0),
                                             Parameter('limit', value=9)])
    assert not result.successful
    assert "'limit'" in result.reason and 'NACK limit' in result.reason
    assert device.log == [('interval', 2.0), ('limit', 9), ('interval', 1.0)]
    assert device.held == {'interval': 1.0, 'limit': 5}
    assert applied == {}
    assert node.get_parameter('interval').value == 1.0 and node.get_parameter('limit').value == 5


def test_a_set_is_checked_whole_before_any_value_is_sent(two_held) -> None:
    node, device, applied = two_held
    result = node.set_parameters_atomically([Parameter('interval', value=2.0),
                                             Parameter('limit', value=9),
                                             Parameter('mode', value='c')])
    assert not result.successful and "is not one of ['a', 'b']" in result.reason
    assert device.log == [] and applied == {}


def test_a_set_the_device_takes_whole_is_sent_and_applied(two_held) -> None:
    node, device, applied = two_held
    result = node.set_parameters_atomically([Parameter('interval', value=2.0),
                                             Parameter('limit', value=9)])
    assert result.successful, result.reason
    assert device.log == [('interval', 2.0), ('limit', 9)]
    assert applied == {'interval': 2.0, 'limit': 9}


def test_busy_refuses_before_anything_is_sent(rig) -> None:
    node, _, applied, device, busy = rig
    busy.append('pan is moving')
    result = set_one(node, 'rate', 30.0)
    assert not result.successful and 'cannot change now: pan is moving' in result.reason
    assert device.sent == [] and 'rate' not in applied


def test_start_up_checks_refuse_invalid_values(rig) -> None:
    node, _, applied, device, _ = rig
    assert not set_one(node, 'rate', 500.0).successful  # descriptor range (rclpy)
    result = set_one(node, 'scales', [1.0, 11.0])  # element range (check_value)
    assert not result.successful and 'element 11.0 outside [-10.0, 10.0]' in result.reason
    result = set_one(node, 'mode', 'c')
    assert not result.successful and "is not one of ['a', 'b']" in result.reason
    result = set_one(node, 'low', 2.0)  # group check with the current high
    assert not result.successful and 'low 2.0 above high 1.0' in result.reason
    assert applied == {} and device.sent == []


def test_a_group_check_sees_every_value_of_an_atomic_set(rig) -> None:
    node, _, applied, _, _ = rig
    result = node.set_parameters_atomically([Parameter('low', value=2.0),
                                             Parameter('high', value=3.0)])
    assert result.successful, result.reason
    assert applied == {'low': 2.0, 'high': 3.0}


def test_read_only_and_reconfigure_parameters_are_refused_with_the_reason(rig) -> None:
    node, registry, _, _, _ = rig
    result = set_one(node, 'names', ['y'])
    assert not result.successful and 'read-only' in result.reason
    result = set_one(node, 'host', 'example.org')
    assert not result.successful and "'host' needs reconfigure" in result.reason
    assert registry.specs['host'].change is Change.RECONFIGURE
    with pytest.raises(ValueError, match='read-only'):
        registry.make_runtime('names', print)


def test_start_up_runs_the_same_checks(node) -> None:
    registry = ParameterRegistry(node)
    with pytest.raises(ParameterError, match=r'element 11\.0 outside'):
        declare(node, 'scales', [11.0], 'scales', value_range=(-10.0, 10.0), registry=registry)
    declare(node, 'low', 5.0, 'low', registry=registry)
    declare(node, 'high', 1.0, 'high', registry=registry)

    def ordered(value_of) -> None:
        if value_of('low') > value_of('high'):
            raise ValueError('bad')

    registry.add_check(['low', 'high'], ordered)
    with pytest.raises(ParameterError, match='parameter high/low: bad'):
        registry.check_all()


def test_a_secret_is_taken_from_the_overrides_without_being_declared() -> None:
    with DomainLease() as domain:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        node = Node('secret_test', context=context,
                    parameter_overrides=[Parameter('password', value='s3cret'),
                                         Parameter('pin', value=1234)])
        events: list[object] = []
        node.add_on_set_parameters_callback(
            lambda parameters: events.extend(parameters) or SetParametersResult(successful=True))
        try:
            taken = take_secret(node, 'password')
            assert taken is not None and taken.value == 's3cret'
            assert not node.has_parameter('password')
            assert take_secret(node, 'pin').value == 1234  # the caller checks the type
            assert take_secret(node, 'absent') is None
            assert events == []  # the capture refused first: no other callback saw a value
            value = declare(node, 'password', '********', 'password', read_only=True,
                            ignore_override=True)
            assert value == '********'
        finally:
            node.destroy_node()
            rclpy.shutdown(context=context)
