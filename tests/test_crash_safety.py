"""Crash safety: a node started while the device is mid-motion takes over cleanly.

The virtual gimbal runs in this process (so the test sees every request line the device
model receives); a node moves the pan axis slowly toward a far target and is killed with
SIGKILL half way; the device keeps moving. A new node is then started: its joint_states must
resume with the live positions (no jump to zero or to the target), it must send no motion
command of its own (the device still runs the old move, nothing stops or redirects it), and
~/stop and a new move must work.
"""

from __future__ import annotations

import itertools
import signal
import threading

import pytest
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_common.ros.testing import RosTestClient, joint_positions
from gimbal_driver_common.testing import DomainLease, ManagedProcess, wait_for
from gimbal_driver_common.virtual_gimbal import make_server
from gimbal_msgs.action import MoveTo

pytestmark = pytest.mark.ros

PKG = 'gimbal_driver_common'
NODE = 'virtual_gimbal'
SLOW = 0.25        # rad/s: the move lasts long enough to kill the node in the middle of it
FAR = 2.5          # rad
MOTION_VERBS = ('MOVE', 'JOG', 'STOP', 'HOME', 'RESET')


class RecordingDevice:
    """Wraps the virtual gimbal's request handler: every request line, in order."""

    def __init__(self, device) -> None:
        self.lines: list[str] = []
        self._lock = threading.Lock()
        handle = device.handle

        def recorded(line: str) -> str:
            with self._lock:
                self.lines.append(line.strip())
            return handle(line)

        device.handle = recorded

    def motion_commands(self, since: int = 0) -> list[str]:
        with self._lock:
            return [line for line in self.lines[since:] if line.split()[:1]
                    and line.split()[0].upper() in MOTION_VERBS]

    def mark(self) -> int:
        with self._lock:
            return len(self.lines)


def start_node(domain: int, port: int) -> ManagedProcess:
    return ManagedProcess.ros(PKG, 'virtual_gimbal_node', domain, [
        '--ros-args', '-p', f'port:={port}', '-p', 'reconnect_period:=0.2',
        '-p', 'publish_rate:=20.0'])


def test_new_node_takes_over_a_device_in_motion_after_sigkill() -> None:
    server, device = make_server(0)
    recorder = RecordingDevice(device)
    with DomainLease() as domain, RosTestClient(domain) as ros:
        states = ros.subscribe('/joint_states', JointState)
        first = start_node(domain, server.port)
        second = None
        try:
            ros.wait_for_message('/joint_states', JointState, timeout=60)
            ros.publish('/joint_command', JointState(name=['pan'], position=[FAR],
                                                     velocity=[SLOW]))
            wait_for(lambda: device.axes['pan'].position > 0.3, 30, 'the pan move under way')
            first.send_signal(signal.SIGKILL)
            first.process.wait(10)
            assert device.axes['pan'].target == pytest.approx(FAR), 'the device kept moving'

            mark = recorder.mark()
            states_before = len(states)
            second = start_node(domain, server.port)
            fresh = ros.wait_for_message('/joint_states', JointState, timeout=60)
            # the first sample of the new node is the live position, not 0 and not the target
            live = device.axes['pan'].position
            pan = joint_positions(fresh)['pan']
            assert 0.3 < pan < FAR - 0.1
            assert abs(pan - live) < SLOW * 2.0, (pan, live)
            # no jump: successive samples advance by at most the axis speed times their gap
            wait_for(lambda: len(states) > states_before + 10, 30, '10 joint_states')
            samples = list(states)[states_before:]
            for before, after in itertools.pairwise(samples):
                gap = ((after.header.stamp.sec - before.header.stamp.sec)
                       + (after.header.stamp.nanosec - before.header.stamp.nanosec) * 1e-9)
                step = joint_positions(after)['pan'] - joint_positions(before)['pan']
                assert -1e-6 <= step <= SLOW * max(gap, 0.0) + 0.01, (step, gap)
            # the new node sent nothing that moves or stops the axes on its own
            assert recorder.motion_commands(mark) == []
            assert device.axes['pan'].target == pytest.approx(FAR)

            stopped = ros.call(Trigger, f'/{NODE}/stop', Trigger.Request())
            assert stopped.success, stopped.message
            wait_for(lambda: device.axes['pan'].target is None, 10, 'the device to stop')
            assert any(c.upper().startswith('STOP') for c in recorder.motion_commands(mark))
            result, _, _ = ros.run_action(MoveTo, f'/{NODE}/move_to', MoveTo.Goal(
                joint_names=['pan', 'tilt'], positions=[0.2, -0.1]), timeout=60)
            assert result.success, result.message
            assert device.axes['pan'].position == pytest.approx(0.2, abs=0.02)
        finally:
            first.stop()
            if second is not None:
                second.stop()
            server.stop()
    log = second.output() if second is not None else ''
    assert 'Traceback' not in log, log
