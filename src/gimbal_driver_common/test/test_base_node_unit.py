"""Base-node logic that needs rclpy but no device: parameters and scan joint choice."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import rclpy
import rclpy.executors
from rclpy.event_handler import EventHandler
from rclpy.parameter import Parameter

from gimbal_driver_common.config import scan_joints
from gimbal_driver_common.ros import messages
from gimbal_driver_common.ros.base_node import GimbalDriverNode
from gimbal_driver_common.ros.look_at import LookAtRefused
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_driver_testing import DomainLease, wait_for
from gimbal_msgs.action import LookAt
from gimbal_msgs.msg import GimbalStatus

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
        assert scan_joints(node.config) == ['pan', 'tilt']
        assert node.limits['slider'].position_max == 1.0
    finally:
        node.destroy_node()


def test_scan_uses_first_two_joints_without_pan_tilt_names(context) -> None:
    node = make(context, joint_names=['yaw', 'pitch', 'roll'])
    try:
        assert scan_joints(node.config) == ['yaw', 'pitch']
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


def test_torque_constants_default_to_none(context) -> None:
    """joint_states effort is current x torque_constants (test_effort.py); none by default."""
    node = make(context)
    try:
        assert node.torque_constants == {}
        assert list(node.get_parameter('torque_constants').value) == []
        assert 'N*m/A' in node.describe_parameter('torque_constants').description
    finally:
        node.destroy_node()


@pytest.mark.parametrize(('value', 'message'), [
    ([0.5, 1.0], "'torque_constants': 2 values but joint_names has 3"),
    ([0.5, 1.0, -1.0], "'torque_constants': -1.0 is not a finite torque constant > 0"),
    ([0.5, 1.0, 0.0], "'torque_constants': 0.0 is not a finite"),
    ([0.5, 1.0, math.inf], "'torque_constants': inf is not a finite"),
])
def test_invalid_torque_constants_are_refused_at_start(context, value, message) -> None:
    with pytest.raises(ParameterError, match=message):
        make(context, torque_constants=value)


def test_torque_constants_apply_at_run_time_and_bad_ones_are_refused(context) -> None:
    node = make(context, torque_constants=[2.0, 0.5, 2.0])
    try:
        assert node.torque_constants == {'slider': 2.0, 'pan': 0.5, 'tilt': 2.0}
        result = node.set_parameters([Parameter('torque_constants', value=[1.0])])[0]
        assert not result.successful and 'joint_names has 3' in result.reason
        assert node.torque_constants == {'slider': 2.0, 'pan': 0.5, 'tilt': 2.0}
        result = node.set_parameters([Parameter('torque_constants', value=[0.1, 0.2, 0.3])])[0]
        assert result.successful, result.reason
        assert node.torque_constants == {'slider': 0.1, 'pan': 0.2, 'tilt': 0.3}
        empty = Parameter('torque_constants', Parameter.Type.DOUBLE_ARRAY, [])
        assert node.set_parameters([empty])[0].successful
        assert node.torque_constants == {}
    finally:
        node.destroy_node()


# ~/look_at set-up (ros/look_at.py): which description, and clear refusals. ThreeAxisNode's
# package (this test module) installs no description.
# the reference driver's chain (test/pan_tilt.urdf: a copy, so this package's tests read
# only its own files)
VIRTUAL_GIMBAL = Path(__file__).resolve().parent / 'pan_tilt.urdf'


def look_at_refusal(context, **overrides) -> str:
    node = make(context, **overrides)
    try:
        with pytest.raises(LookAtRefused) as refused:
            node.look_at_server.plan_look_at(LookAt.Goal())
        return str(refused.value)
    finally:
        node.destroy_node()


def test_look_at_without_an_installed_description_asks_for_description_file(context) -> None:
    message = look_at_refusal(context)
    assert 'look_at is unavailable' in message and 'description_file' in message


def test_look_at_names_an_unreadable_description(context) -> None:
    message = look_at_refusal(context, description_file='/nonexistent/rig.urdf')
    assert 'cannot read the description /nonexistent/rig.urdf' in message


def test_look_at_refuses_a_description_whose_joints_the_node_lacks(context) -> None:
    message = look_at_refusal(context, description_file=str(VIRTUAL_GIMBAL),
                              joint_names=['slider', 'yaw', 'pitch'])
    assert "joint 'pan' is not one of the node's joints ['slider', 'yaw', 'pitch']" in message


def test_look_at_refuses_an_unknown_aim_frame(context) -> None:
    message = look_at_refusal(context, description_file=str(VIRTUAL_GIMBAL),
                              look_at_frame='lens')
    assert "no link 'lens'" in message


def test_look_at_with_a_usable_description_still_waits_for_an_active_node(context) -> None:
    message = look_at_refusal(context, description_file=str(VIRTUAL_GIMBAL))
    assert 'not active' in message


def test_look_at_parses_the_description_at_the_first_goal_not_at_start(context,
                                                                       tmp_path) -> None:
    """URDF parsing only when a feature needs it (issue 47 item 2): a description that is
    there but does not parse lets the node start, and the first aiming goal names why."""
    broken = tmp_path / 'broken.urdf'
    broken.write_text('<robot name="rig"><link name="base_link"></robot>')
    node = make(context, description_file=str(broken))
    try:
        assert node.look_at_server.aiming_error == ''  # not read yet
        with pytest.raises(LookAtRefused, match='cannot parse the URDF'):
            node.look_at_server.plan_look_at(LookAt.Goal())
        assert 'cannot parse the URDF' in node.look_at_server.aiming_error
    finally:
        node.destroy_node()


def test_axis_state_code_in_axis_details() -> None:
    """A ROS-free adapter gives an AxisStateCode (no gimbal_msgs import); ~/status has it."""
    import logging

    from gimbal_driver_common.controller import ControllerConfig, GimbalController, LinkState
    from gimbal_driver_common.device import AxisStateCode, Device, StatusReport
    from gimbal_driver_common.joint_command import JointLimits
    from gimbal_driver_common.ros import messages
    from gimbal_msgs.msg import AxisState

    class Report(StatusReport):
        def parts(self):
            return []

        def axis_details(self, joint):
            return {'state': AxisStateCode.FAULT if joint == 'pan' else AxisStateCode.PLAYBACK,
                    'calibrated': True}

    class Named(Device):
        def __init__(self):
            super().__init__()
            self.capabilities.status = Report()

        open = read = move = jog = stop = lambda self, *args: None

    config = ControllerConfig(['pan', 'tilt'], {n: JointLimits() for n in ('pan', 'tilt')})
    ctl = GimbalController(Named(), config, logging.getLogger('test'))
    ctl.link_state = LinkState.CONNECTED
    msg = messages.gimbal_status(ctl, ['pan', 'tilt'])
    assert [a.state for a in msg.axes] == [AxisState.STATE_FAULT, AxisState.STATE_PLAYBACK]
    assert all(a.calibrated for a in msg.axes)


def test_publishers_carry_no_qos_event_handlers_subscriptions_keep_theirs(context) -> None:
    """rclpy's executor checks every Python waitable after each wake-up, before it reaches
    the joint_command subscription; the node's publishers add none (base_node
    ``create_publisher``), while joint_command keeps its incompatible-QoS warnings."""
    node = make(context)
    try:
        handlers = [w for w in node.waitables if isinstance(w, EventHandler)]
        publishers, subscriptions = list(node.publishers), list(node.subscriptions)
        assert publishers and subscriptions
        # two per subscription (incompatible QoS, incompatible type), none per publisher
        assert len(handlers) == 2 * len(subscriptions)
    finally:
        node.destroy_node()


def test_status_is_built_only_while_someone_subscribes(context, monkeypatch) -> None:
    """~/status (10 Hz) is built and published only while the topic has a subscriber."""
    node = make(context)
    built: list[GimbalStatus] = []

    def counted(*args: object) -> GimbalStatus:
        built.append(real(*args))
        return built[-1]

    real = messages.gimbal_status
    monkeypatch.setattr(messages, 'gimbal_status', counted)
    received: list[GimbalStatus] = []
    try:
        node._publish_status()
        assert built == []
        node.create_subscription(GimbalStatus, '~/status', received.append, 10)
        wait_for(lambda: node._status_pub.get_subscription_count() == 1, 10.0,
                 'the subscription to match')
        before = len(built)  # the node's own 10 Hz job may have built some since it matched
        node._publish_status()
        assert len(built) > before
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        wait_for(lambda: executor.spin_once(timeout_sec=0.1) or received, 10.0,
                 'the status message')
        assert received[0].connection == built[0].connection
        executor.shutdown()
    finally:
        node.destroy_node()
