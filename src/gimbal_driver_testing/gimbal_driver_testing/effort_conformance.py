"""The conformance test of joint_states ``effort``: torque (N*m) or force (N) only.

sensor_msgs/JointState defines effort as N*m or N, and ros2_control's effort state
interface reads it as such, so a device's motor current (A) is ``~/status``
``AxisState.current`` and reaches ``effort`` only through the ``torque_constants`` the
user sets. Mixed into :class:`~gimbal_driver_testing.conformance.DriverConformance`
(split for size).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import pytest
from sensor_msgs.msg import JointState

from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance_rig import ConformanceHelpers, ConformanceRig
from gimbal_msgs.msg import GimbalStatus

#: joint_states messages looked at for "effort stays empty"
LOOKED_AT = 5


class EffortConformance(ConformanceHelpers):
    """Effort as torque through the real node (attributes: see DriverConformance)."""

    joints: Sequence[str]
    #: the device reports motor current: ~/status ``current`` is finite on every axis
    reports_current: bool = False

    def _status(self, rig: ConformanceRig) -> GimbalStatus:
        """A connected ~/status whose axes all carry a current (when the device has one)."""
        assert rig.ros is not None

        def ready(msg: GimbalStatus) -> bool:
            return (msg.connection == GimbalStatus.CONNECTION_CONNECTED and (
                not self.reports_current or all(math.isfinite(a.current) for a in msg.axes)))

        return rig.ros.wait_for_message(f'/{self.node_name}/status', GimbalStatus, ready,
                                        timeout=30)

    def _efforts(self, rig: ConformanceRig) -> list[list[float]]:
        assert rig.ros is not None
        received = rig.ros.subscribe('joint_states', JointState)
        seen = len(received)
        wait_for(lambda: len(received) >= seen + LOOKED_AT, 30.0,
                 f'{LOOKED_AT} joint_states messages')
        return [list(m.effort) for m in received[seen:seen + LOOKED_AT]]

    @pytest.mark.ros
    def test_effort_is_empty_without_torque_constants(self, rig: ConformanceRig) -> None:
        """Default parameters: no effort, and ~/status has the current in A (or NaN)."""
        assert self._efforts(rig) == [[]] * LOOKED_AT
        status = self._status(rig)
        assert [a.name for a in status.axes] == list(self.joints)
        assert all(math.isnan(a.effort) for a in status.axes)
        if not self.reports_current:
            assert all(math.isnan(a.current) for a in status.axes)

    @pytest.mark.ros
    def test_effort_is_current_times_the_torque_constants(
            self, conformance_rig: ConformanceRig) -> None:
        """``torque_constants`` set: effort = current x k, the same sample in joint_states
        and ~/status; a device without current still publishes no effort."""
        rig = conformance_rig
        constants = [0.5 * (index + 1) for index in range(len(self.joints))]
        rig.start_node(f'torque_constants:={constants}')
        assert rig.ros is not None
        status = self._status(rig)
        if not self.reports_current:
            assert self._efforts(rig) == [[]] * LOOKED_AT
            assert all(math.isnan(a.current) and math.isnan(a.effort) for a in status.axes)
            return
        for axis, k in zip(status.axes, constants, strict=True):
            assert axis.effort == pytest.approx(axis.current * k, rel=1e-9, abs=1e-12)
        # joint_states carries the torque of the samples ~/status reports the current of
        statuses = rig.ros.subscribe(f'/{self.node_name}/status', GimbalStatus)
        states = rig.ros.subscribe('joint_states', JointState)
        first_status, first_state = len(statuses), len(states)

        def torque(status: GimbalStatus) -> list[float]:
            return [a.current * k for a, k in zip(status.axes, constants, strict=True)]

        def matched() -> bool:
            wanted = [torque(s) for s in statuses[first_status:]]
            return any(len(m.effort) == len(self.joints) and any(
                list(m.effort) == pytest.approx(t, rel=1e-9, abs=1e-12) for t in wanted)
                for m in states[first_state:])

        wait_for(matched, 30.0, 'joint_states effort equal to a ~/status current x '
                 f'torque_constants {constants}')
