"""The guarded device procedure policy (``guarded.py``) on a controller and an in-memory
device, no ROS: how a procedure is refused, runs, and ends. Waits are for conditions; a
run that never ends fails at ``future.result``'s timeout."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.device import (
    Device,
    DeviceInfo,
    DeviceProcedure,
    JointSample,
    Moves,
    ProcedureProgress,
)
from gimbal_driver_common.errors import DeviceRefused, InvalidRequest, LinkError
from gimbal_driver_common.guarded import GuardedProcedures
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.policies import Motion
from gimbal_driver_common.presets import PresetStore
from gimbal_driver_common.scan import ScanRequest
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.controller_rig import running_controller

#: s a run may take to end once it should; reached only when the policy misses the end
ENDS_WITHIN = 5.0
#: a poll period no test outlasts: only a wake (cancel request, ~/stop) ends that wait
FOREVER = 600.0


class RestingDevice(Device):
    """Two joints at rest unless a test says one moves; records what was sent."""

    def __init__(self) -> None:
        super().__init__()
        self.moving: dict[str, bool] = {}
        self.sent: list[tuple[str, object]] = []
        self.down = False  # the link is lost and stays lost

    def open(self) -> DeviceInfo:
        if self.down:
            raise ConnectionRefusedError('nobody listening')
        return DeviceInfo('resting')

    def read(self) -> JointSample:
        if self.down:
            raise ConnectionResetError('peer reset')
        return JointSample({'pan': 0.0, 'tilt': 0.0}, moving=dict(self.moving))

    def move(self, moves: Moves) -> None:
        self.sent.append(('move', sorted(moves)))

    def jog(self, velocities: dict[str, float]) -> None:
        self.sent.append(('jog', sorted(velocities)))

    def stop(self, joints: Sequence[str] | None = None) -> None:
        self.sent.append(('stop', None if joints is None else list(joints)))


class Scripted(DeviceProcedure):
    """Done at poll ``done_at`` (None: never); counts its starts and polls."""

    name = 'the scripted procedure'
    group = 'a scripted procedure'
    cancelled = 'scripted procedure cancelled'
    superseded = 'scripted procedure superseded'
    timed_out = 'scripted procedure not done in time'

    def __init__(self, done_at: int | None = 1, joints: Sequence[str] = (),
                 period: float = 0.001, **attributes: object) -> None:
        self.done_at, self.joints, self.period = done_at, list(joints), period
        self.program: str | None = None
        self.starts = self.polls = 0
        self.polled = threading.Event()
        for key, value in attributes.items():
            setattr(self, key, value)

    def busy(self) -> str | None:
        return self.program

    def start(self) -> None:
        self.starts += 1

    def poll(self, elapsed: float) -> ProcedureProgress:
        self.polls += 1
        self.polled.set()
        done = self.done_at is not None and self.polls >= self.done_at
        return ProcedureProgress(f'poll {self.polls}', f'done after {self.polls}' if done
                                 else None)


@pytest.fixture
def device() -> RestingDevice:
    return RestingDevice()


@pytest.fixture
def controller(device: RestingDevice) -> Iterator[GimbalController]:
    limits = {joint: JointLimits(-1.0, 1.0, 2.0) for joint in ('pan', 'tilt')}
    config = ControllerConfig(['pan', 'tilt'], limits, publish_rate=200.0,
                              reconnect_period=0.01)
    with running_controller(device, config, logging.getLogger('test_guarded')) as ctl:
        yield ctl


@pytest.fixture
def motion(controller: GimbalController, tmp_path) -> Motion:
    return Motion(controller, PresetStore(str(tmp_path / 'presets.yaml')))


@pytest.fixture
def procedures(motion: Motion) -> GuardedProcedures:
    return GuardedProcedures(motion)


@pytest.fixture
def pool() -> Iterator[ThreadPoolExecutor]:
    with ThreadPoolExecutor(2) as executor:
        yield executor
        executor.shutdown(wait=False, cancel_futures=True)  # a run a test left hanging


def start_run(pool: ThreadPoolExecutor, procedures: GuardedProcedures, procedure: Scripted,
              reports: list[str] | None = None,
              cancelled: Callable[[], bool] = lambda: False) -> Future:
    """Run ``procedure`` on the pool; return once it polled (it is running)."""
    future = pool.submit(procedures.run, lambda: procedure,
                         (reports if reports is not None else []).append, cancelled)
    wait_for(lambda: procedure.polled.is_set() or future.done(), ENDS_WITHIN, 'a first poll')
    return future


def test_a_procedure_runs_to_its_result_with_feedback(procedures) -> None:
    procedure, reports = Scripted(done_at=3), []
    assert procedures.run(lambda: procedure, reports.append) == 'done after 3'
    assert procedure.starts == 1 and reports == ['poll 1', 'poll 2', 'poll 3']


def test_it_is_done_only_once_the_joints_it_moves_rest(procedures, controller, device,
                                                       pool) -> None:
    class Turning(Scripted):
        """Its result is there at once, while the device still turns the joint."""

        def start(self) -> None:
            device.moving['tilt'] = True
            wait_for(lambda: controller.moving('tilt'), ENDS_WITHIN, 'tilt turning')

    procedure, reports = Turning(done_at=1, joints=['tilt']), []
    future = start_run(pool, procedures, procedure, reports)
    wait_for(lambda: any(r.endswith(' (moving)') for r in reports), ENDS_WITHIN, 'moving')
    assert not future.done()
    device.moving['tilt'] = False
    assert future.result(ENDS_WITHIN).startswith('done after')


def test_a_timeout_stops_the_joints_the_device_moves(procedures, device) -> None:
    procedure = Scripted(done_at=None, joints=['tilt'], timeout=0.0)
    with pytest.raises(DeviceRefused, match='scripted procedure not done in time'):
        procedures.run(lambda: procedure, lambda state: None)
    assert device.sent == [('stop', ['tilt'])]


def test_a_cancel_request_ends_it_at_once_and_stops_the_joints(procedures, device,
                                                               pool) -> None:
    """The wait between polls is as long as the test may run: the wake ends it."""
    requested = threading.Event()
    procedure = Scripted(done_at=None, joints=['tilt'], period=FOREVER)
    future = start_run(pool, procedures, procedure, cancelled=requested.is_set)
    requested.set()
    procedures.wake()  # what the action's cancel callback does
    with pytest.raises(DeviceRefused, match='scripted procedure cancelled'):
        future.result(ENDS_WITHIN)
    assert device.sent == [('stop', ['tilt'])]


def test_stop_ends_it_at_once(procedures, controller, pool) -> None:
    future = start_run(pool, procedures, Scripted(done_at=None, period=FOREVER))
    controller.stop()
    with pytest.raises(DeviceRefused, match='scripted procedure cancelled'):
        future.result(ENDS_WITHIN)


def test_the_policies_hear_of_a_stop_before_the_generation_moves_on(procedures,
                                                                     controller) -> None:
    """Else a procedure that polls between the two ends "superseded" after a ~/stop."""
    before, seen = controller.motion_generation, []
    controller.halt_hooks.append(lambda: seen.append(controller.motion_generation))
    controller.stop()
    assert seen == [before]
    assert controller.motion_generation == before + 1


def test_a_newer_move_ends_it_without_stopping_the_move(procedures, motion, device,
                                                        pool) -> None:
    future = start_run(pool, procedures, Scripted(done_at=None, joints=['tilt']))
    motion.start_move(['tilt'], [0.2])
    with pytest.raises(DeviceRefused, match='scripted procedure superseded'):
        future.result(ENDS_WITHIN)
    assert device.sent == [('move', ['tilt'])]  # the newer move owns the axis now


def test_link_loss_ends_it(procedures, controller, device, pool) -> None:
    future = start_run(pool, procedures, Scripted(done_at=None))
    device.down = True
    with pytest.raises(LinkError, match='device link lost during the scripted procedure'):
        future.result(ENDS_WITHIN)
    assert not controller.connected


def test_motion_ends_a_procedure_that_must_hold_still(procedures, device, pool) -> None:
    future = start_run(pool, procedures, Scripted(done_at=None, hold_still=True))
    device.moving['pan'] = True
    with pytest.raises(DeviceRefused, match=r'moved during the scripted procedure \(pan '
                                            r'moving.*not trusted'):
        future.result(ENDS_WITHIN)


@pytest.mark.parametrize('busy', ['program', 'scan', 'moving'])
def test_refused_while_busy_nothing_started(procedures, motion, controller, device,
                                            busy) -> None:
    procedure = Scripted()
    if busy == 'program':
        procedure.program = 'a preset loop is running'
        expected = 'preset loop'
    elif busy == 'scan':
        motion.start_scan(ScanRequest('sector', -0.2, 0.2, 0.0, 0.0, 1.0, 0.0, 0.0))
        expected = 'a scan is running'
    else:
        device.moving['pan'] = True
        wait_for(lambda: controller.moving('pan'), ENDS_WITHIN, 'pan moving')
        expected = 'pan moving'
    with pytest.raises(DeviceRefused, match=expected):
        procedures.run(lambda: procedure, lambda state: None)
    assert procedure.starts == 0
    if busy == 'scan':
        motion.stop_scan()


def test_one_at_a_time(procedures, pool) -> None:
    requested = threading.Event()
    first = start_run(pool, procedures, Scripted(done_at=None, period=FOREVER),
                      cancelled=requested.is_set)
    second = Scripted()
    with pytest.raises(DeviceRefused, match='refused: a scripted procedure is already running'):
        procedures.run(lambda: second, lambda state: None)
    assert second.starts == 0
    requested.set()
    procedures.wake()
    with pytest.raises(DeviceRefused, match='cancelled'):
        first.result(ENDS_WITHIN)
    assert procedures.run(lambda: second, lambda state: None) == 'done after 1'


def test_a_refused_start_and_an_inactive_controller_start_nothing(procedures,
                                                                  controller) -> None:
    class BadRequest(Scripted):
        def start(self) -> None:
            raise InvalidRequest('takes no joint names')

    with pytest.raises(InvalidRequest, match='no joint names'):
        procedures.run(BadRequest, lambda state: None)
    controller.active = False
    procedure = Scripted()
    with pytest.raises(DeviceRefused, match='not active'):
        procedures.run(lambda: procedure, lambda state: None)
    assert procedure.starts == 0
