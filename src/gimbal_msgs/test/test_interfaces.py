"""Every gimbal_msgs type imports, has its constants, and round-trips through rclpy
serialization. Needs only this package and rclpy (its test_depend), so it runs under
``colcon test --packages-select gimbal_msgs``; the process-boundary tests, which use the
shared test helpers, are gimbal_driver_common's test/test_gimbal_msgs_cross_process.py."""

from __future__ import annotations

import importlib

import pytest
from rclpy.serialization import deserialize_message, serialize_message


def interface_names(kind: str) -> list[str]:
    """The types rosidl generated in ``gimbal_msgs.<kind>`` (not Foo_Request and the like)."""
    module = importlib.import_module(f'gimbal_msgs.{kind}')
    return sorted(name for name in dir(module) if name[:1].isupper() and '_' not in name
                  and isinstance(getattr(module, name), type))


MESSAGES, SERVICES, ACTIONS = (interface_names(kind) for kind in ('msg', 'srv', 'action'))


def test_every_interface_of_cmakelists_is_generated() -> None:
    """The package's own CMakeLists.txt names what rosidl generates."""
    from pathlib import Path

    cmake = (Path(__file__).resolve().parent.parent / 'CMakeLists.txt').read_text()
    listed = {line.strip().strip('"') for line in cmake.splitlines()
              if line.strip().startswith('"') and line.strip().endswith(('.msg"', '.srv"',
                                                                          '.action"'))}
    generated = {f'{kind}/{name}.{kind}' for kind, names in
                 (('msg', MESSAGES), ('srv', SERVICES), ('action', ACTIONS)) for name in names}
    assert generated == listed


def sample(kind: type) -> object:
    """An instance with non-default values in every field we can fill simply."""
    msg = kind()
    for field, type_name in kind.get_fields_and_field_types().items():
        if type_name == 'string':
            setattr(msg, field, f'{field}-value')
        elif type_name in ('double', 'float'):
            setattr(msg, field, 1.25)
        elif type_name.startswith(('uint', 'int')):
            setattr(msg, field, 3)
        elif type_name == 'boolean':
            setattr(msg, field, True)
        elif type_name == 'sequence<string>':
            setattr(msg, field, ['a', 'b'])
        elif type_name == 'sequence<double>':
            setattr(msg, field, [0.5, -0.5])
    return msg


def test_constants_are_defined() -> None:
    from gimbal_msgs.msg import AxisState, GimbalStatus, PlaybackStatus
    from gimbal_msgs.srv import Calibrate, LoadTrajectory, StartScan

    assert PlaybackStatus.FULL_STOP == 5 and PlaybackStatus.SMS_MOTORS_STOPPED == 13
    assert StartScan.Request.PATTERN_ZIGZAG == 'zigzag'
    assert LoadTrajectory.Request.MODE_TIMELAPSE_SMS == 2
    assert GimbalStatus.CONNECTION_CONNECTED == 2 and AxisState.STATE_FAULT == 7
    assert Calibrate.Request.MARK_END == 1


@pytest.mark.parametrize('name', MESSAGES)
def test_message_serialization_round_trip(name: str) -> None:
    kind = getattr(importlib.import_module('gimbal_msgs.msg'), name)
    msg = sample(kind)
    assert deserialize_message(serialize_message(msg), kind) == msg


@pytest.mark.parametrize('name', SERVICES)
def test_service_serialization_round_trip(name: str) -> None:
    kind = getattr(importlib.import_module('gimbal_msgs.srv'), name)
    for part in (kind.Request, kind.Response):
        msg = sample(part)
        assert deserialize_message(serialize_message(msg), part) == msg


@pytest.mark.parametrize('name', ACTIONS)
def test_action_serialization_round_trip(name: str) -> None:
    kind = getattr(importlib.import_module('gimbal_msgs.action'), name)
    for part in (kind.Goal, kind.Result, kind.Feedback):
        msg = sample(part)
        assert deserialize_message(serialize_message(msg), part) == msg
