"""Base-node logic that needs rclpy but no device: parameters and scan joint choice."""

from __future__ import annotations

import pytest
import rclpy
from rclpy.parameter import Parameter

from gimbal_driver_common.ros.base_node import GimbalDriverNode
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_driver_common.testing import DomainLease

pytestmark = pytest.mark.ros


class ThreeAxisNode(GimbalDriverNode):
    DEFAULT_JOINT_NAMES = ('slider', 'pan', 'tilt')
    DEFAULT_POSITION_MIN = (-1.0, -3.0, -1.5)
    DEFAULT_POSITION_MAX = (1.0, 3.0, 1.5)
    DEFAULT_VELOCITY_MAX = (0.5, 1.0, 1.0)


@pytest.fixture
def context():
    with DomainLease() as domain:
        ctx = rclpy.Context()
        rclpy.init(context=ctx, domain_id=domain)
        yield ctx
        rclpy.shutdown(context=ctx)


def make(context, **overrides) -> ThreeAxisNode:
    params = [Parameter(k, value=v) for k, v in overrides.items()]
    return ThreeAxisNode('three_axis', context=context, parameter_overrides=params)


def test_scan_sweeps_pan_and_tilt_by_name_whatever_their_order(context) -> None:
    node = make(context)
    try:
        assert node.joint_names == ['slider', 'pan', 'tilt']
        assert node.scan_joints() == ['pan', 'tilt']
        assert node.limits['slider'].position_max == 1.0
    finally:
        node.destroy_node()


def test_scan_uses_first_two_joints_without_pan_tilt_names(context) -> None:
    node = make(context, joint_names=['yaw', 'pitch', 'roll'])
    try:
        assert node.scan_joints() == ['yaw', 'pitch']
    finally:
        node.destroy_node()


@pytest.mark.parametrize(
    ('overrides', 'message'),
    [
        ({'velocity_max': [1.0, 1.0]}, 'velocity_max has 2 values'),
        ({'position_min': [2.0, 0.0, 0.0]}, 'position_min 2.0 > position_max 1.0'),
        ({'command_timeout': -5.0}, 'command_timeout'),
        ({'joint_names': ['pan', 'pan', 'tilt']}, 'unique'),
    ],
)
def test_invalid_parameters_name_the_parameter(context, overrides, message) -> None:
    with pytest.raises(ParameterError, match=message):
        make(context, **overrides)
