"""The ~/look_at checks every driver's process-level tests run against its simulator.

A driver's tests subclass :class:`LookAtSuite` as ``TestLookAt`` and give a
``look_at_rig`` fixture (simulator and node processes, see :func:`look_at_rig_against`)
that yields a :class:`LookAtRig`.

Target points are made from the package's URDF by forward kinematics (the point 5 m
along the camera's line of sight at a chosen pan and tilt), so the expected joint
positions are exact whatever the mounting offsets; the description tests check the
forward kinematics and the REP-103 signs on their own.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest
from geometry_msgs.msg import Point, PointStamped
from sensor_msgs.msg import JointState

from gimbal_driver_common.kinematics import AimingChain
from gimbal_driver_testing import ManagedProcess, wait_for
from gimbal_driver_testing.ros import RosTestClient, joint_positions
from gimbal_msgs.action import LookAt
from gimbal_msgs.msg import GimbalStatus

GOAL_SUCCEEDED = 4
GOAL_ABORTED = 6


def installed_description(package: str, name: str | None = None) -> Path:
    """share/<package>/urdf/<name or package>.urdf of the built workspace."""
    from ament_index_python.packages import get_package_share_directory

    return Path(get_package_share_directory(package)) / 'urdf' / (name or f'{package}.urdf')


class LookAtCheck:
    """Sends ~/look_at goals to ``node`` and checks what comes back and what moves."""

    def __init__(self, ros: RosTestClient, node: str, description: Path,
                 distance: float = 5.0) -> None:
        self.ros = ros
        self.node = node
        self.chain = AimingChain.from_file(description)
        self.joints = [self.chain.pan_joint, self.chain.tilt_joint]
        self.distance = distance

    def held_positions(self) -> dict[str, float]:
        """Current positions of the joints look_at does not move (e.g. a slider)."""
        state = joint_positions(self.ros.wait_for_message('joint_states', JointState))
        return {n: p for n, p in state.items() if n not in self.joints}

    def point_for(self, pan: float, tilt: float) -> tuple[float, float, float]:
        """The base-frame point that the camera sees dead centre at (pan, tilt)."""
        pose = self.chain.aim_pose({**self.held_positions(), self.joints[0]: pan,
                                    self.joints[1]: tilt})
        x, y, z = pose[:3, 3] + self.distance * pose[:3, 0]
        return float(x), float(y), float(z)

    def look_at(self, point: Sequence[float], frame: str = 'base_link', speed: float = 0.0,
                timeout: float = 90.0):
        goal = LookAt.Goal(speed=speed)
        goal.target = PointStamped(point=Point(x=point[0], y=point[1], z=point[2]))
        goal.target.header.frame_id = frame
        return self.ros.run_action(LookAt, f'/{self.node}/look_at', goal, timeout=timeout)

    def look_and_reach(self, pan: float, tilt: float, tolerance: float = 0.02) -> object:
        """look_at the point seen at (pan, tilt); assert the result, feedback and joints."""
        result, status, feedback = self.look_at(self.point_for(pan, tilt))
        assert result.success, result.message
        assert status == GOAL_SUCCEEDED
        assert list(result.joint_names) == self.joints
        assert list(result.positions) == pytest.approx([pan, tilt], abs=tolerance), result.positions
        # feedback and result come on different entities, in no set order: a goal already
        # at its target has one feedback, which can come after the result
        wait_for(lambda: feedback, 20.0, 'the feedback of the goal')
        assert all(len(f.positions) == 2 for f in feedback)
        self.ros.wait_for_message(
            'joint_states', JointState,
            lambda m: all(abs(joint_positions(m).get(j, math.inf) - p) <= tolerance
                          for j, p in zip(self.joints, (pan, tilt), strict=True)),
            timeout=30.0)
        return result

    def commanded_targets(self) -> list[float]:
        status = self.ros.wait_for_message(f'/{self.node}/status', GimbalStatus)
        return [a.target_position for a in status.axes if a.name in self.joints]

    def refused(self, point: Sequence[float], expected: str, frame: str = 'base_link',
                speed: float = 0.0,
                device_commands: Callable[[], object] | None = None) -> object:
        """look_at must answer success=false naming ``expected`` and send nothing
        (``device_commands()``, e.g. the simulator's state, must not change)."""
        targets = self.commanded_targets()
        commands = device_commands() if device_commands else None
        result, status, _ = self.look_at(point, frame=frame, speed=speed)
        assert not result.success
        assert status == GOAL_ABORTED
        assert 'nothing sent' in result.message and expected in result.message, result.message
        assert list(result.joint_names) == self.joints
        # no new target reached the device: ~/status still shows the old ones
        assert _same(self.commanded_targets(), targets)
        if device_commands is not None:
            assert device_commands() == commands
        return result


def _same(a: Sequence[float], b: Sequence[float]) -> bool:
    return len(a) == len(b) and all(
        (math.isnan(x) and math.isnan(y)) or x == y for x, y in zip(a, b, strict=True))



@contextlib.contextmanager
def node_against_sim(domain: int, sim: ManagedProcess, start_node: Callable[[], ManagedProcess],
                     timeout: float = 40.0) -> Iterator[RosTestClient]:
    """``start_node()`` (which waits for the simulator first), then a test client once
    joint_states flow; both processes are stopped afterwards, whatever happened."""
    node = None
    try:
        node = start_node()
        with RosTestClient(domain) as ros:
            ros.wait_for_message('joint_states', JointState, timeout=timeout, fresh=False)
            yield ros
    finally:
        if node is not None:
            node.stop()
        sim.stop()


@dataclass
class LookAtRig:
    """What the suite needs from a driver: the check, and the device's state as the
    simulator reports it (any comparable value that changes when a command arrives)."""

    check: LookAtCheck
    device_state: Callable[[], object]
    simulator: object = None  # the simulator's control handle, for the driver's own checks


@contextlib.contextmanager
def look_at_rig_against(package: str, domain: int, sim: ManagedProcess,
                        start_node: Callable[[], ManagedProcess],
                        device_state: Callable[[], object], node: str | None = None,
                        description: Path | None = None) -> Iterator[LookAtRig]:
    """The rig a driver's ``look_at_rig`` fixture yields: the node against its simulator
    (:func:`node_against_sim`), checked against the package's installed URDF."""
    with node_against_sim(domain, sim, start_node) as ros:
        check = LookAtCheck(ros, node or package, description or installed_description(package))
        yield LookAtRig(check, device_state)


class LookAtSuite:
    """The look_at cases every driver passes: ahead, left, up, beyond the limits, other
    frames. The node must run with a tilt lower limit above ``BELOW_LIMIT``."""

    UP = 0.5  # rad of tilt for the "up" case
    BELOW_LIMIT = -1.2  # rad of tilt: beyond every rig's lower tilt limit

    def test_look_at_straight_ahead(self, look_at_rig: LookAtRig) -> None:
        look_at_rig.check.look_and_reach(0.0, 0.0)

    def test_look_at_to_the_left(self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        assert check.point_for(math.pi / 2, 0.0)[1] > 0.0  # REP-103: left is +y
        check.look_and_reach(math.pi / 2, 0.0)

    def test_look_at_up(self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        assert check.point_for(0.0, self.UP)[2] > check.point_for(0.0, 0.0)[2]  # up is +z
        check.look_and_reach(0.0, self.UP)

    def test_look_at_beyond_the_tilt_limit_is_refused_and_sends_nothing(
            self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        check.refused(check.point_for(0.0, self.BELOW_LIMIT), 'position_min',
                      device_commands=look_at_rig.device_state)

    def test_look_at_in_another_frame_is_refused(self, look_at_rig: LookAtRig) -> None:
        check = look_at_rig.check
        check.refused(check.point_for(0.0, 0.0), 'transform the point first', frame='map',
                      device_commands=look_at_rig.device_state)
