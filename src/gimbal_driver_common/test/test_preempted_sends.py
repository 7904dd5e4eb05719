"""A stop preempts the exchange in flight (``LinkLock.preempt``: Capture's answer book
ends it at once, so the stop never waits on its answer). What it preempted is not lost
where the stop did not cover it: the dead-man stop of pan must not cancel tilt's move.
A device whose ``move`` waits for its answer under the link lock until a stop preempts
it, against the real controller, command path and link lock (no ROS)."""

from __future__ import annotations

import threading
from collections.abc import Iterator, Sequence

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.device import Device, DeviceInfo, JointSample, Moves
from gimbal_driver_common.errors import Preempted
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.controller_rig import running_controller

JOINTS = ('pan', 'tilt')
TIMEOUT = 10.0


class AnsweringLate(Device):
    """The first ``move`` waits for its answer until a stop preempts it (raises
    :class:`Preempted`, nothing applied); every other request is answered at once."""

    def __init__(self) -> None:
        super().__init__()
        self.positions = dict.fromkeys(JOINTS, 0.0)
        self.sent: list[tuple[str, object]] = []
        self.lock = threading.Lock()
        self.in_flight = threading.Event()      # the first move waits for its answer
        self._preempt = threading.Event()
        self.hold_first = True
        self.link_lock.preempt = self._preempt.set

    def open(self) -> DeviceInfo:
        return DeviceInfo('late', 'SN1', '1.0')

    def read(self) -> JointSample:
        with self.lock:
            return JointSample(dict(self.positions), dict.fromkeys(JOINTS, 0.0))

    def move(self, moves: Moves) -> None:
        if self.hold_first:
            self.hold_first = False
            self.in_flight.set()
            self._preempt.wait()
            with self.lock:
                self.sent.append(('preempted', dict(moves)))
            raise Preempted(f'move {sorted(moves)}: preempted by a stop')
        with self.lock:
            self.sent.append(('move', dict(moves)))
            for joint, (target, _) in moves.items():
                self.positions[joint] = target

    def jog(self, velocities: dict[str, float]) -> None:
        with self.lock:
            self.sent.append(('jog', dict(velocities)))

    def stop(self, joints: Sequence[str] | None = None) -> None:
        with self.lock:
            self.sent.append(('stop', None if joints is None else list(joints)))

    def kinds(self) -> list[str]:
        with self.lock:
            return [kind for kind, _ in self.sent]


@pytest.fixture
def rig() -> Iterator[tuple[GimbalController, AnsweringLate]]:
    device = AnsweringLate()
    limits = {j: JointLimits(-1.0, 1.0, 2.0) for j in JOINTS}
    config = ControllerConfig(
        joint_names=list(JOINTS), limits=limits, publish_rate=200.0, command_timeout=0.5,
        reconnect_period=0.01, goal_tolerance=0.01, move_timeout=2.0)
    with running_controller(device, config, first_sample=False) as ctl:
        yield ctl, device


def test_a_stop_of_another_joint_sends_the_preempted_joint_command_again(rig) -> None:
    ctl, device = rig
    ctl.command(['tilt'], [0.3], [])            # the command thread's move waits
    wait_for(device.in_flight.is_set, TIMEOUT, 'the move in flight')
    ctl.stop_joints(['pan'])                     # the dead-man stop of pan preempts it
    wait_for(lambda: ('move', {'tilt': (0.3, None)}) in device.sent, TIMEOUT,
             "tilt's move sent again after the stop")
    assert device.kinds() == ['preempted', 'stop', 'move']
    assert ctl.rejections.counts()['refused'] == {}


def test_a_stop_of_the_same_joint_leaves_the_preempted_command_undone(rig) -> None:
    ctl, device = rig
    ctl.command(['tilt'], [0.3], [])
    wait_for(device.in_flight.is_set, TIMEOUT, 'the move in flight')
    ctl.stop_joints(['tilt'])
    wait_for(lambda: 'preempted' in device.kinds(), TIMEOUT, 'the move preempted')
    ctl.command(['pan'], [0.1], [])              # the command thread is free again
    wait_for(lambda: ('move', {'pan': (0.1, None)}) in device.sent, TIMEOUT, "pan's move")
    assert device.kinds() == ['preempted', 'stop', 'move']  # tilt's never again


def move_to_in_thread(ctl: GimbalController) -> tuple[threading.Thread, list]:
    """``send_moves`` of tilt (what ~/move_to does) in a thread; what it ended with."""
    done: list[BaseException | None] = []

    def move_to() -> None:
        try:
            ctl.send_moves({'tilt': (0.4, None)})
            done.append(None)
        except BaseException as exc:  # noqa: BLE001 - the test reads it
            done.append(exc)

    thread = threading.Thread(target=move_to)
    thread.start()
    return thread, done


def test_a_move_to_preempted_by_a_stop_of_another_joint_goes_out_after_it(rig) -> None:
    ctl, device = rig
    thread, done = move_to_in_thread(ctl)
    wait_for(device.in_flight.is_set, TIMEOUT, 'the move in flight')
    ctl.stop_joints(['pan'])
    thread.join(TIMEOUT)
    assert done == [None]
    assert device.kinds() == ['preempted', 'stop', 'move']


def test_a_move_to_preempted_by_the_whole_stop_raises(rig) -> None:
    ctl, device = rig
    thread, done = move_to_in_thread(ctl)
    wait_for(device.in_flight.is_set, TIMEOUT, 'the move in flight')
    ctl.stops.send(None)
    thread.join(TIMEOUT)
    assert len(done) == 1 and isinstance(done[0], Preempted), done
    assert device.kinds() == ['preempted', 'stop']
