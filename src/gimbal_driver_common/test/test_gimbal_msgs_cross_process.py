"""Every gimbal_msgs type crosses a process boundary as a topic, service or action: a peer
process (gimbal_msgs_peer.py) echoes each back. Here, not in gimbal_msgs, because it uses
this package's test helpers (domain leases, processes, the rclpy test client), and this
package depends on gimbal_msgs, not the other way round."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_testing import DomainLease, ManagedProcess, ros_env
from gimbal_driver_testing.ros import RosTestClient

pytestmark = pytest.mark.ros

PEER = Path(__file__).resolve().parent / 'gimbal_msgs_peer.py'
sys.path.insert(0, str(PEER.parent))
from gimbal_msgs_peer import ACTIONS, MESSAGES, SERVICES  # noqa: E402


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


@pytest.fixture(scope='module')
def peer():
    with DomainLease() as domain:
        process = ManagedProcess([sys.executable, str(PEER)],
                                 ros_env(domain), name='gimbal_msgs_peer')
        try:
            process.wait_for_output('peer ready', timeout=30)
            with RosTestClient(domain) as ros:
                yield ros
        finally:
            process.stop()


@pytest.mark.parametrize('name', MESSAGES)
def test_message_crosses_process_boundary(peer: RosTestClient, name: str) -> None:
    kind = getattr(importlib.import_module('gimbal_msgs.msg'), name)
    msg = sample(kind)
    peer.subscribe(f'echo_out/{name}', kind)
    peer.publish(f'echo_in/{name}', msg)
    assert peer.wait_for_message(f'echo_out/{name}', kind, fresh=False) == msg


@pytest.mark.parametrize('name', SERVICES)
def test_service_crosses_process_boundary(peer: RosTestClient, name: str) -> None:
    kind = getattr(importlib.import_module('gimbal_msgs.srv'), name)
    reply = peer.call(kind, f'srv/{name}', sample(kind.Request))
    assert reply.success and reply.message == f'{name} served'


@pytest.mark.parametrize('name', ACTIONS)
def test_action_crosses_process_boundary(peer: RosTestClient, name: str) -> None:
    kind = getattr(importlib.import_module('gimbal_msgs.action'), name)
    goal = sample(kind.Goal)
    if name == 'LookAt':  # the nested PointStamped crosses too
        goal.target.header.frame_id = 'base_link'
        goal.target.point.x, goal.target.point.y, goal.target.point.z = 1.5, -0.5, 2.0
    result, status, _feedback = peer.run_action(kind, f'action/{name}', goal)
    assert result.success and result.message == f'{name} done'
    assert status == 4  # GoalStatus.STATUS_SUCCEEDED
    if name == 'MoveTo':
        assert list(result.positions) == [0.5, -0.5]
    if name == 'LookAt':
        assert list(result.positions) == [1.5, -0.5, 2.0]
    if name == 'LookAtGeo':  # sample() fills latitude, longitude and altitude with 1.25
        assert list(result.positions) == [1.25, 1.25, 1.25]
