"""joint_states effort is torque (N*m) or force (N), never amperes; ~/status has the current.

In-process: messages built from a controller's state (the ``torque_constants`` parameter
on a node is in test_base_node_unit.py). Through a real node against each driver's
simulator: the conformance suite (testing/effort_conformance.py).
"""

from __future__ import annotations

import logging
import math

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController, LinkState
from gimbal_driver_common.device import Device, JointSample
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.ros import messages


def fill(*args):
    """joint_states from a fresh message (no test shares one)."""
    return messages.JointStateMessage().fill(*args)

JOINTS = ['pan', 'tilt']


class Still(Device):
    open = read = move = jog = stop = lambda self, *args: None


def controller(sample: JointSample | None) -> GimbalController:
    config = ControllerConfig(list(JOINTS), {n: JointLimits() for n in JOINTS})
    ctl = GimbalController(Still(), config, logging.getLogger('test'))
    ctl.link_state = LinkState.CONNECTED
    ctl.latest = sample
    return ctl


SAMPLE = JointSample({'pan': 0.1, 'tilt': -0.2}, {'pan': 0.0, 'tilt': 0.0},
                     currents={'pan': 1.5, 'tilt': -0.25})


def test_without_torque_constants_effort_is_empty_and_status_has_the_current() -> None:
    assert list(fill(SAMPLE, JOINTS).effort) == []
    assert list(fill(SAMPLE, JOINTS, {}).effort) == []
    status = messages.gimbal_status(controller(SAMPLE), JOINTS)
    assert [a.current for a in status.axes] == [1.5, -0.25]
    assert all(math.isnan(a.effort) for a in status.axes)


def test_effort_is_current_times_the_joints_torque_constant() -> None:
    constants = {'pan': 0.8, 'tilt': 2.0}
    msg = fill(SAMPLE, JOINTS, constants)
    assert list(msg.name) == JOINTS
    assert list(msg.effort) == pytest.approx([1.5 * 0.8, -0.25 * 2.0])
    status = messages.gimbal_status(controller(SAMPLE), JOINTS, constants)
    assert [a.effort for a in status.axes] == pytest.approx([1.2, -0.5])
    assert [a.current for a in status.axes] == [1.5, -0.25]  # still amperes


def test_a_device_without_current_gives_no_effort_whatever_the_constants() -> None:
    sample = JointSample({'pan': 0.1, 'tilt': -0.2})
    assert list(fill(sample, JOINTS, {'pan': 1.0, 'tilt': 1.0}).effort) == []
    status = messages.gimbal_status(controller(sample), JOINTS, {'pan': 1.0, 'tilt': 1.0})
    assert all(math.isnan(a.current) and math.isnan(a.effort) for a in status.axes)


def test_a_joint_without_a_current_reading_is_nan_in_an_effort_of_full_length() -> None:
    """sensor_msgs/JointState: effort is empty or one entry per name."""
    sample = JointSample({'pan': 0.1, 'tilt': -0.2}, currents={'tilt': 0.5})
    effort = list(fill(sample, JOINTS, {'pan': 1.0, 'tilt': 3.0}).effort)
    assert len(effort) == 2 and math.isnan(effort[0]) and effort[1] == pytest.approx(1.5)


def test_status_before_configure_has_nan_current() -> None:
    status = messages.gimbal_status(None, JOINTS)
    assert all(math.isnan(a.current) and math.isnan(a.effort) for a in status.axes)
