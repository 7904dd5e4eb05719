"""~/look_at set-up in-process (no device): which description, and clear refusals."""

from __future__ import annotations

from pathlib import Path

import pytest
import rclpy
from rclpy.parameter import Parameter

pytest.importorskip('urdf_parser_py', reason='needs urdfdom-py (make build)')
from gimbal_driver_common.ros.base_node import GimbalDriverNode
from gimbal_driver_common.ros.look_at import LookAtRefused
from gimbal_driver_common.testing import DomainLease
from gimbal_msgs.action import LookAt

pytestmark = pytest.mark.ros

VIRTUAL_GIMBAL = Path(__file__).parents[1] / 'urdf' / 'virtual_gimbal.urdf'


class PanTiltNode(GimbalDriverNode):
    """A device-less node; its package (this test module) installs no description."""


@pytest.fixture
def context():
    with DomainLease() as domain:
        ctx = rclpy.Context()
        rclpy.init(context=ctx, domain_id=domain)
        yield ctx
        rclpy.shutdown(context=ctx)


def refusal(context, **overrides) -> str:
    params = [Parameter(k, value=v) for k, v in overrides.items()]
    node = PanTiltNode('pan_tilt', context=context, parameter_overrides=params)
    try:
        with pytest.raises(LookAtRefused) as refused:
            node.plan_look_at(LookAt.Goal())
        return str(refused.value)
    finally:
        node.destroy_node()


def test_a_package_without_a_description_asks_for_description_file(context) -> None:
    message = refusal(context)
    assert 'look_at is unavailable' in message and 'description_file' in message


def test_an_unreadable_description_is_named(context) -> None:
    message = refusal(context, description_file='/nonexistent/rig.urdf')
    assert 'cannot read the description /nonexistent/rig.urdf' in message


def test_a_description_whose_joints_the_node_lacks_is_refused(context) -> None:
    message = refusal(context, description_file=str(VIRTUAL_GIMBAL),
                      joint_names=['yaw', 'pitch'])
    assert "joint 'pan' is not one of the node's joints ['yaw', 'pitch']" in message


def test_an_unknown_aim_frame_is_refused(context) -> None:
    message = refusal(context, description_file=str(VIRTUAL_GIMBAL), look_at_frame='lens')
    assert "no link 'lens'" in message


def test_a_usable_description_still_waits_for_an_active_node(context) -> None:
    message = refusal(context, description_file=str(VIRTUAL_GIMBAL))
    assert 'not active' in message
