"""A stop preempts the exchange in flight (issue 44 item 1): GimbalController + CaptureDevice
against the simulator in-process over TCP; no ROS.

Each case holds the link lock for a request the simulator never answers, with a timeout far
longer than the test waits, then stops. The verdict is an order of events, not a time: the
stop's bytes reach the simulator and ~/stop answers while the request's own wait would still
run, and the request ends with Preempted, not with its timeout (before, the stop waited for
the lock until that timeout: the request ended with DeviceTimeout first).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Iterator

import pytest

from capture_driver.device import CaptureDevice, CaptureSettings
from capture_driver.errors import Preempted
from capture_driver.protocol import COMMANDS
from capture_driver.sim import CaptureSimulator, PedestalModel
from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_testing import wait_for

LOG = logging.getLogger('test_stop_preempts')
#: the held request's own timeout (s): the test never waits this long for anything
HELD_TIMEOUT_S = 60.0


class Rig:
    def __init__(self) -> None:
        self.sim = CaptureSimulator(PedestalModel(time_scale=8.0), tcp_port=0).start()
        settings = CaptureSettings(
            joint_names=['pan', 'tilt'], axis_ids=[1, 2], joint_directions=[-1.0, 1.0],
            gear_ratios=[1.0, 1.0], transport='tcp', host='127.0.0.1', port=self.sim.tcp.port,
            keepalive_period=0.0, default_speed=1.0, acceleration=6.0, status_period=0.1)
        self.device = CaptureDevice(settings)
        config = ControllerConfig(
            joint_names=['pan', 'tilt'],
            limits={'pan': JointLimits(-math.pi, math.pi, 1.5),
                    'tilt': JointLimits(-math.pi / 2, math.pi / 2, 1.5)},
            publish_rate=20.0, command_timeout=0.5, reconnect_period=0.2)
        self.controller = GimbalController(self.device, config, LOG)
        self.controller.open()
        self.controller.activate()
        wait_for(lambda: self.controller.latest is not None, 10.0, 'first sample')

    def close(self) -> None:
        self.sim.model.request_faults.clear()
        self.controller.shutdown()
        self.sim.stop()

    def sent(self, name: str) -> list[bytes]:
        """The data of every ``name`` request the simulator received, in order."""
        opcode = COMMANDS[name].opcode
        return [f.data for f in list(self.sim.model.requests) if f.opcode == opcode]

    def hold_and_run(self, request: Callable[[], object]) -> tuple[threading.Thread,
                                                                    list[BaseException]]:
        """``request`` in a thread that holds the device's link lock throughout."""
        raised: list[BaseException] = []

        def run() -> None:
            try:
                with self.device.client.link_lock:
                    request()
            except BaseException as exc:  # noqa: BLE001 - what it ended with is the verdict
                raised.append(exc)

        thread = threading.Thread(target=run, daemon=True, name='holder')
        thread.start()
        return thread, raised


@pytest.fixture
def rig() -> Iterator[Rig]:
    rig = Rig()
    yield rig
    rig.close()


def test_a_stop_preempts_a_getter_under_the_lock_whose_answer_never_comes(rig) -> None:
    client = rig.device.client
    rig.sim.model.request_faults.mute('IMU_GetRoll')
    asked = len(rig.sent('IMU_GetRoll'))
    holder, raised = rig.hold_and_run(
        lambda: client.request('IMU_GetRoll', timeout=HELD_TIMEOUT_S))
    wait_for(lambda: len(rig.sent('IMU_GetRoll')) > asked, 10.0, 'the getter sent')
    stops = len(rig.sent('SCN_StopScan'))
    answer = rig.controller.stop()
    assert len(rig.sent('SCN_StopScan')) > stops  # the whole stop went out
    assert answer.startswith('all axes stopped'), answer
    holder.join(10.0)
    assert not holder.is_alive() and len(raised) == 1
    assert isinstance(raised[0], Preempted), repr(raised[0])  # not its timeout


def test_a_stop_preempts_a_jog_set_up_whose_step_is_never_answered(rig) -> None:
    """The holder's later steps never go out: the axis is not set jogging after the stop."""
    client = rig.device.client
    client.timeout = HELD_TIMEOUT_S  # the set-up's steps wait this long for their ACKs
    rig.sim.model.request_faults.mute('MOT_SetAcceleration')
    asked = len(rig.sent('MOT_SetAcceleration'))
    speeds = len(rig.sent('MOT_SetSpeed'))
    holder, raised = rig.hold_and_run(lambda: client.jog(1, 20.0, 60.0))
    wait_for(lambda: len(rig.sent('MOT_SetAcceleration')) > asked, 10.0, 'the step sent')
    answer = rig.controller.stop()
    assert answer.startswith('all axes stopped'), answer
    holder.join(10.0)
    assert not holder.is_alive() and len(raised) == 1
    assert isinstance(raised[0], Preempted), repr(raised[0])
    # only the stop's speed 0 (one per axis): the jog's own MOT_SetSpeed never went out
    assert [d for d in rig.sent('MOT_SetSpeed')[speeds:] if any(d)] == []
    assert rig.sim.model.axes[1].velocity == 0.0
