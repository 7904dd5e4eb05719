"""The stop part of the conformance suite: every stop reaches rest, through the real
transport, client and node.

* a stop with one step answered late (the simulators' ``delay``, beyond the request
  timeout) still stops the axis: each message of the stop in turn;
* a stop the device takes and drops (``ignore``: the stop message answered as always, not
  acted on, for 1 s longer than the axis needs to brake) is sent again, and the axis comes to
  rest: the dead-man stop of a jog, read from the simulator's receive log;
* ``~/stop`` never answers success while an axis still moves, names the axis, and answers
  success once the axis rests.

Each driver's simulator handle names its stop messages (``SimHandle.stop_requests``) and
the one that stops a jogging axis (``SimHandle.stop_request``). The checks are behaviour
(what reached the simulator, in what order; "at rest eventually"), never timings.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import pytest
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance_rig import ConformanceHelpers, ConformanceRig
from gimbal_driver_testing.ros import joint_positions

#: s a step of the stop is answered late: beyond every driver's request timeout
LATE_S = 2.0
#: s beyond its braking time (speed / stop_deceleration + stop_margin) the device drops the
#: stop: at least one resend falls inside, and ~/stop's wait ends inside
IGNORE_EXTRA_S = 1.0
#: s a stop is dropped at most where the test lifts the ignore itself once it has seen
#: what it checks (a generous outer bound)
HELD_S = 60.0
#: s the axis gets to rest once the device takes the stop again (a generous outer bound)
REST_TIMEOUT_S = 30.0


def request_name(logged: str) -> str:
    """The request name of a receive-log entry ("STOP pan", "stop_actuators 3")."""
    return logged.split()[0] if logged else ''


class StopConformance(ConformanceHelpers):
    """Mixed into :class:`~gimbal_driver_testing.conformance.DriverConformance`."""

    jog: tuple[str, float]
    joints: Sequence[str]

    # ------------------------------------------------------------------ helpers
    def stop_names(self, rig: ConformanceRig) -> tuple[tuple[str, ...], str]:
        assert rig.sim is not None
        names, jog_stop = tuple(rig.sim.stop_requests), rig.sim.stop_request
        assert names and jog_stop in names, (
            f'{type(rig.sim).__name__} names no stop_requests/stop_request')
        return names, jog_stop

    def braking_time(self, rig: ConformanceRig) -> float:
        """s the node gives the jogging axis to rest after a stop, by its parameters."""
        speed = abs(self.jog[1])
        deceleration = float(rig.ros.get_parameter(self.node_name, 'stop_deceleration'))
        margin = float(rig.ros.get_parameter(self.node_name, 'stop_margin'))
        return speed / deceleration + margin

    def start_jog(self, rig: ConformanceRig) -> None:
        """Jog until the simulator shows the axis moving, the jog fed all the while: the
        dead-man stop comes ``command_timeout`` after this returns, not before."""
        joint, velocity = self.jog

        def jogging() -> bool:
            rig.ros.publish('joint_command', JointState(name=[joint], velocity=[velocity]))
            return rig.sim.moving(joint)

        wait_for(jogging, 20.0, f'{joint} to start jogging', interval=0.05)

    def motion_after_the_last_stop(self, rig: ConformanceRig, mark: int) -> list[str]:
        """The motion requests (not stops) the device received after the last stop it
        received since ``mark``: commands the node sent after its stop."""
        names, _ = self.stop_names(rig)
        since = rig.sim.requests()[mark:]
        last_stop = max((i for i, logged in enumerate(since) if request_name(logged) in names),
                        default=-1)
        return [logged for logged in since[last_stop + 1:]
                if rig.sim.motion(logged) and request_name(logged) not in names]

    def logged_since(self, rig: ConformanceRig, mark: int, name: str) -> list[int]:
        """Indices (from ``mark``) of the receive-log entries of request ``name``."""
        return [i for i, logged in enumerate(rig.sim.requests()[mark:])
                if request_name(logged) == name]

    @contextmanager
    def device_fault(self, rig: ConformanceRig) -> Iterator[None]:
        """Afterwards: the faults cleared, the axis at rest and back where it was (the
        jogs of these tests run it far; the next test's jog must not meet a limit). The
        jog starts from the middle of the joint's range, so it meets no limit either."""
        joint = self.jog[0]
        here = joint_positions(rig.ros.wait_for_message('joint_states', JointState))[joint]
        index = list(self.joints).index(joint)
        middle = (rig.ros.get_parameter(self.node_name, 'position_min')[index]
                  + rig.ros.get_parameter(self.node_name, 'position_max')[index]) / 2
        if not math.isfinite(middle):  # an endless axis: from where it is
            middle = here
        rig.ros.publish('joint_command', JointState(name=[joint], position=[middle]))
        self.wait_positions(rig.ros, {joint: middle})
        self.wait_stopped(rig, joint, 'the axis to rest at the middle of its range')
        try:
            yield
        finally:
            rig.sim.clear()
            rig.ros.call(Trigger, self.srv('stop'), Trigger.Request())
            self.wait_stopped(rig, joint, 'the axis to rest after the test')
            rig.ros.publish('joint_command', JointState(name=[joint], position=[here]))
            self.wait_positions(rig.ros, {joint: here})

    # -------------------------------------------------------------------- tests
    @pytest.mark.ros
    def test_a_stop_with_a_step_answered_late_still_stops(self, rig: ConformanceRig) -> None:
        names, _ = self.stop_names(rig)
        joint = self.jog[0]
        for name in names:
            with self.device_fault(rig):
                self.start_jog(rig)
                rig.sim.delay(name, LATE_S)
                mark = rig.sim.mark()
                rig.ros.call(Trigger, self.srv('stop'), Trigger.Request(), timeout=60.0)
                self.wait_stopped(rig, joint, f'the stop with {name} answered {LATE_S:g} s '
                                  'late')
                assert rig.sim.changes_since(mark), f'no stop reached the simulator ({name})'

    @pytest.mark.ros
    def test_a_dropped_dead_man_stop_is_sent_again_until_the_axis_rests(
            self, rig: ConformanceRig) -> None:
        _, jog_stop = self.stop_names(rig)
        joint = self.jog[0]
        with self.device_fault(rig):
            self.start_jog(rig)
            # the device drops the stop until this test has seen it sent again, then takes
            # it (``ignore ... 0``): the outage is ended by events, not by a window that a
            # slow run could let pass before the dead-man stop even went out
            rig.sim.ignore(jog_stop, HELD_S)
            mark, logged = rig.sim.mark(), len(rig.node.output())
            # one more jog once the ignore is armed: the dead-man stop counts from it (on a
            # loaded machine start_jog's own jog may expire before the ignore is armed; the
            # device then took that stop, before the mark)
            rig.ros.publish('joint_command', JointState(name=[joint], velocity=[self.jog[1]]))
            # no further joint_command: the dead-man stop goes out and the device drops it
            wait_for(lambda: 'expired' in rig.node.output()[logged:], 20.0,
                     'the dead-man stop')
            wait_for(lambda: self.logged_since(rig, mark, jog_stop), 20.0,
                     f'the dead-man stop ({jog_stop}) to reach the simulator')
            assert rig.sim.moving(joint), (
                f'the ignored stop stopped the axis: {rig.sim.requests()[mark:]}')
            wait_for(lambda: len(self.logged_since(rig, mark, jog_stop)) >= 2, REST_TIMEOUT_S,
                     f'the stop sent again while the device drops it: '
                     f'{rig.sim.requests()[mark:]}')
            wait_for(lambda: 'stop not confirmed' in rig.node.output()[logged:], 20.0,
                     "the node's 'stop not confirmed' line")
            assert rig.sim.moving(joint), 'the axis came to rest though every stop was dropped'
            rig.sim.ignore(jog_stop, 0.0)  # the device takes the next one
            self.wait_stopped(rig, joint, 'the stop sent again once the device takes it')
            output = rig.node.output()[logged:]
            assert output.count('stop not confirmed') == 1, output  # once per episode

    @pytest.mark.ros
    def test_stop_never_answers_success_while_an_axis_moves(self, rig: ConformanceRig) -> None:
        _, jog_stop = self.stop_names(rig)
        joint = self.jog[0]
        window = self.braking_time(rig) + IGNORE_EXTRA_S
        with self.device_fault(rig):
            self.start_jog(rig)
            rig.sim.ignore(jog_stop, window)  # at once: before the dead-man stop
            mark = rig.sim.mark()
            reply = rig.ros.call(Trigger, self.srv('stop'), Trigger.Request(), timeout=60.0)
            still = rig.sim.moving(joint)
            newer = self.motion_after_the_last_stop(rig, mark)
            # the motion is a newer command's where the node sent one after its last stop:
            # a jog start_jog published before ~/stop can reach the node after the answer
            # (a crowded run: rest confirmed, success, then the node jogged again)
            assert not (reply.success and still and not newer), (
                f'success while {joint} moves: {reply.message}; the device received '
                f'{rig.sim.requests()[mark:]}')
            if still and not newer:  # the usual case: the device still drops the stop
                assert not reply.success and joint in reply.message, reply.message
                assert 'stop not confirmed' in reply.message, reply.message
            self.wait_stopped(rig, joint, 'the stop sent again once the device takes it')
            rig.sim.clear()
            reply = rig.ros.call(Trigger, self.srv('stop'), Trigger.Request(), timeout=60.0)
            assert reply.success, reply.message
