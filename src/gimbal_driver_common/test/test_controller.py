"""The ROS-free controller and policies against an in-memory fake device, in milliseconds."""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections.abc import Callable, Iterator, Sequence

import pytest

from gimbal_driver_common.controller import (
    STOP_CHECK_IDLE_S,
    STOP_CHECK_S,
    WATCHDOG_IDLE_PERIOD_S,
    ControllerConfig,
    GimbalController,
    is_moving,
)
from gimbal_driver_common.device import (
    Device,
    DeviceInfo,
    DevicePresets,
    DeviceScans,
    Homing,
    JointSample,
    Moves,
    PostedWrite,
)
from gimbal_driver_common.errors import (
    DeviceRefused,
    DeviceTimeout,
    GimbalError,
    InvalidRequest,
    LinkError,
    Unsupported,
    as_gimbal_error,
    device_boundary,
)
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.periodic import Periodic
from gimbal_driver_common.policies import HomingSuperseded, Motion
from gimbal_driver_common.presets import PresetStore
from gimbal_driver_common.scan import ScanRequest
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.controller_rig import running_controller

JOINTS = ['pan', 'tilt']


class FakeDevice(Device):
    """Two axes that move a fixed step per read toward their target; records what it got."""

    def __init__(self, step: float = 0.05) -> None:
        super().__init__()
        self.step = step
        self.positions = dict.fromkeys(JOINTS, 0.0)
        self.targets: dict[str, float] = {}
        self.jogs: dict[str, float] = {}
        self.sent: list[tuple[str, object]] = []
        self.lock = threading.Lock()
        self.open_failures = 0  # opens that fail before one succeeds
        self.opens = 0
        self.broken = False  # read() raises: the link dropped
        self.refuse: str | None = None
        self.nack_moves = False
        self.move_threads: list[str] = []  # the thread each move() ran in
        self.hold_moves: threading.Event | None = None  # move() waits for it (a slow ACK)

    def open(self) -> DeviceInfo:
        self.opens += 1
        if self.open_failures > 0:
            self.open_failures -= 1
            raise ConnectionRefusedError('nobody listening')
        self.broken = False
        return DeviceInfo('fake', 'SN1', '1.0')

    def read(self) -> JointSample:
        if self.broken:
            raise ConnectionResetError('peer reset')
        with self.lock:
            velocities = {}
            for joint in JOINTS:
                if joint in self.targets:
                    error = self.targets[joint] - self.positions[joint]
                    delta = math.copysign(min(abs(error), self.step), error)
                    if abs(error) <= self.step:
                        del self.targets[joint]
                else:
                    delta = self.jogs.get(joint, 0.0) * 0.01
                self.positions[joint] += delta
                velocities[joint] = delta / 0.01
            return JointSample(dict(self.positions), velocities)

    def move(self, moves: Moves) -> None:
        self.move_threads.append(threading.current_thread().name)
        if self.hold_moves is not None:
            self.hold_moves.wait()
        if self.nack_moves:
            raise DeviceRefused('device NACK: axis disabled')
        with self.lock:
            self.sent.append(('move', dict(moves)))
            for joint, (target, _) in moves.items():
                self.targets[joint] = target
                self.jogs.pop(joint, None)

    def jog(self, velocities: dict[str, float]) -> None:
        with self.lock:
            self.sent.append(('jog', dict(velocities)))
            self.jogs.update(velocities)

    def stop(self, joints: Sequence[str] | None = None) -> None:
        with self.lock:
            self.sent.append(('stop', None if joints is None else list(joints)))
            for joint in joints or JOINTS:
                self.targets.pop(joint, None)
                self.jogs.pop(joint, None)

    def refusal(self, joints: Sequence[str]) -> str | None:
        return self.refuse

    def kinds(self) -> list[str]:
        with self.lock:
            return [kind for kind, _ in self.sent]


class FakeHoming(Homing):
    def __init__(self, device: FakeDevice) -> None:
        self.device = device

    def home(self, joints, report, cancelled) -> str:
        self.device.move({j: (0.0, None) for j in joints})
        while self.device.targets and not cancelled.is_set():
            report('seeking index')
            cancelled.wait(0.005)
        return 'homed'


class WaitingHoming(Homing):
    """A routine that reports once and then only waits (like Kessler's wait at the begin
    marks): it ends when ``cancelled`` is set, or after ``seconds``."""

    def __init__(self, seconds: float = 30.0) -> None:
        self.seconds = seconds
        self.cancelled: threading.Event | None = None  # the Event the last homing waited on

    def home(self, joints, report, cancelled) -> str:
        self.cancelled = cancelled
        report('moving to the index')
        cancelled.wait(self.seconds)
        return 'at the index'


class SlotZeroPresets(DevicePresets):
    """The device stores slot 0 only; the other slots belong to the YAML store."""

    def __init__(self) -> None:
        self.slot: tuple[str, dict[str, float]] | None = None

    def handles(self, index: int) -> bool:
        return index == 0

    def set(self, index, name, positions) -> str:
        self.slot = (name, positions or {})
        return 'stored on the device'

    def goto(self, index, speed) -> str:
        if self.slot is None:
            raise DeviceRefused('device slot 0 is empty')
        return 'device moving to slot 0'

    def list(self):
        return [(0, self.slot[0], self.slot[1])] if self.slot else []

    def clear(self, index) -> str:
        self.slot = None
        return 'device slot cleared'


class FakeScans(DeviceScans):
    patterns = ('spiral',)

    def __init__(self) -> None:
        self.running = False

    def start(self, request: ScanRequest) -> str:
        self.running = True
        return 'device spiral'

    def stop(self) -> None:
        self.running = False


def config(**overrides) -> ControllerConfig:
    limits = {j: JointLimits(-1.0, 1.0, 2.0) for j in JOINTS}
    values = dict(joint_names=list(JOINTS), limits=limits, publish_rate=500.0,
                  command_timeout=0.05, reconnect_period=0.01, goal_tolerance=0.01,
                  move_timeout=2.0)
    values.update(overrides)
    return ControllerConfig(**values)


@pytest.fixture
def device() -> FakeDevice:
    return FakeDevice()


@pytest.fixture
def controller(device):
    with running_controller(device, config()) as ctl:
        yield ctl


@pytest.fixture
def motion(controller, tmp_path):
    return Motion(controller, PresetStore(str(tmp_path / 'presets.yaml')))


# ------------------------------------------------------------------- errors
def test_boundary_converts_foreign_errors_into_the_hierarchy() -> None:
    assert isinstance(as_gimbal_error(TimeoutError('late')), DeviceTimeout)
    assert isinstance(as_gimbal_error(ConnectionResetError('reset')), LinkError)
    assert isinstance(as_gimbal_error(ValueError('bad')), InvalidRequest)
    error = as_gimbal_error(KeyError('x'))
    assert type(error) is GimbalError and 'KeyError' in str(error)
    with pytest.raises(LinkError), device_boundary():
        raise BrokenPipeError('gone')
    refused = DeviceRefused('NACK 0x2')
    assert as_gimbal_error(refused) is refused


# ------------------------------------------------------- link supervision
def test_open_failure_raises_with_the_reason_and_leaves_it_disconnected(device) -> None:
    device.open_failures = 1
    ctl = GimbalController(device, config(), logging.getLogger('test'))
    with pytest.raises(LinkError, match='nobody listening'):
        ctl.open()
    assert not ctl.connected and 'nobody listening' in ctl.link_error


def test_link_loss_is_reported_then_reconnected_with_a_count(controller, device) -> None:
    changes = []
    controller.on_link_change = lambda: changes.append(controller.connected)
    device.open_failures = 2
    device.broken = True
    wait_for(lambda: controller.reconnects == 1, 2.0, 'the reconnect')
    assert changes[0] is False and changes[-1] is True
    assert controller.connected and controller.link_error == ''
    assert device.opens == 4  # first open, two refused, one accepted
    controller.command(['pan'], [0.5], [])
    wait_for(lambda: abs(controller.positions()['pan'] - 0.5) < 1e-9, 2.0, 'the move')


def test_commands_are_refused_while_disconnected_or_inactive(controller, device) -> None:
    controller.active = False
    with pytest.raises(DeviceRefused, match='not active'):
        controller.command(['pan'], [0.1], [])
    controller.active = True
    device.open_failures = 10**6
    device.broken = True
    wait_for(lambda: not controller.connected, 2.0, 'the link loss')
    with pytest.raises(DeviceRefused, match='not connected'):
        controller.command(['pan'], [0.1], [])
    with pytest.raises(LinkError, match='nothing to stop'):
        controller.stop()


# ------------------------------------------------------------- commands
def test_invalid_commands_send_nothing(controller, device) -> None:
    for names, positions, velocities in [
        (['roll'], [0.1], []), (['pan'], [-math.inf], [math.nan]), (['pan'], [math.inf], []),
        (['pan', 'tilt'], [0.1], []), (['pan'], [5.0], []), (['pan'], [], [9.0]),
    ]:
        with pytest.raises(InvalidRequest):
            controller.command(names, positions, velocities)
    assert device.kinds() == []


def test_nan_joints_are_left_alone_and_all_nan_does_nothing(motion, controller,
                                                           device) -> None:
    controller.command(['pan', 'tilt'], [0.3, math.nan], [])
    wait_for(lambda: device.kinds() == ['move'], 2.0, 'the move of pan alone')
    assert device.sent[0][1] == {'pan': (0.3, None)}
    # nothing but NaN: no send, no refusal even while inactive, a running scan goes on
    motion.start_scan(ScanRequest('sector', -0.2, 0.2, 0.0, 0.0, 1.0, 0.0, 0.0))
    controller.command(['pan', 'tilt'], [math.nan, math.nan], [math.nan, math.nan])
    assert motion.scanning and not motion._scan_stop.is_set()  # not preempted
    motion.stop_scan()
    sent = len(device.sent)
    controller.active = False
    controller.command(['pan', 'tilt'], [math.nan, math.nan], [])
    assert len(device.sent) == sent
    assert controller.rejections.counts() == {'rejected': {}, 'refused': {}}


def test_every_refusal_path_is_counted_by_reason(controller, device) -> None:
    """Validation, inactive, disconnected, the device refusing the axes and a failed send
    all end in the controller's CommandRejections (the node's joint_command part)."""
    rejections = controller.rejections

    def refused(*command: list) -> None:
        with pytest.raises(GimbalError) as caught:
            controller.command(*command)
        rejections.record(caught.value)  # what the node does with it

    refused(['pan'], [5.0], [])
    refused(['pan'], [-5.0], [])
    device.refuse = 'pan drive is off'
    refused(['pan'], [0.1], [])
    device.refuse = None
    controller.active = False
    refused(['pan'], [0.1], [])
    controller.active = True
    device.nack_moves = True
    controller.command(['pan'], [0.2], [])  # accepted; the device refuses the send
    wait_for(lambda: rejections.counts()['refused'].get(
        'failed on the device: refused by the device'), 2.0, 'the failed send')
    device.nack_moves = False
    assert rejections.counts() == {
        'rejected': {'pan: position outside the limits': 2},
        'refused': {'failed on the device: refused by the device': 1,
                    'node not active': 1, 'the device cannot move the axes': 1}}
    device.open_failures = 10**6
    device.broken = True
    wait_for(lambda: not controller.connected, 2.0, 'the link loss')
    refused(['pan'], [0.1], [])
    assert rejections.counts()['refused']['device not connected'] == 1


def test_device_refusal_sends_nothing(controller, device) -> None:
    device.refuse = 'pan drive is off'
    with pytest.raises(DeviceRefused, match='pan drive is off'):
        controller.command(['pan'], [0.1], [])
    controller.command(['pan'], [], [0.0])  # a zero jog (a stop) is never refused
    wait_for(lambda: device.kinds() == ['jog'], 2.0, 'the zero jog')


@contextlib.contextmanager
def link_held(controller: GimbalController):
    """Another thread holds the device's link lock (a send or an exchange in flight) until
    the block ends."""
    taken, done = threading.Event(), threading.Event()

    def hold() -> None:
        with controller.commands.link_lock:
            taken.set()
            done.wait(10.0)

    holder = threading.Thread(target=hold, name='link-holder', daemon=True)
    holder.start()
    assert taken.wait(5.0), 'the link lock was not taken'
    try:
        yield
    finally:
        done.set()
        holder.join(5.0)


def test_newest_command_per_joint_wins(controller, device) -> None:
    with link_held(controller):  # hold the command thread while three commands queue
        controller.command(['pan'], [0.1], [])
        controller.command(['pan'], [0.2], [])
        controller.command(['tilt'], [-0.3], [])
    wait_for(lambda: device.kinds() == ['move'], 2.0, 'one move')
    assert device.sent[0][1] == {'pan': (0.2, None), 'tilt': (-0.3, None)}
    assert controller.commanded_targets == {'pan': 0.2, 'tilt': -0.3}


def test_jog_stops_when_the_watchdog_expires(controller, device) -> None:
    controller.command(['pan'], [], [0.5])
    wait_for(lambda: controller.moving('pan'), 2.0, 'the jog')
    wait_for(lambda: ('stop', ['pan']) in device.sent, 2.0, 'the dead-man stop')
    assert controller.watchdog.jogging == []


class PeriodRecorder(Periodic):
    """A Periodic that records every period set for each job (what the thread would wait)."""

    def __init__(self) -> None:
        super().__init__(name='housekeeping')
        self.set: list[tuple[Callable[[], object], float]] = []

    def periods(self, callback: Callable[[], object]) -> list[float]:
        """The periods set for ``callback``'s job, in order."""
        return [period for job, period in list(self.set) if job == callback]

    def add(self, period: float, callback: Callable[[], object]) -> None:
        self.set.append((callback, period))
        super().add(period, callback)

    def set_period(self, callback: Callable[[], object], period: float) -> None:
        self.set.append((callback, period))
        super().set_period(callback, period)


@contextlib.contextmanager
def recorded_periods(device: Device) -> Iterator[tuple[GimbalController, PeriodRecorder]]:
    """An active controller whose housekeeping periods are recorded."""
    periodic = PeriodRecorder()
    ctl = GimbalController(device, config(), logging.getLogger('test'), periodic=periodic)
    try:
        ctl.open()
        ctl.activate()
        yield ctl, periodic
    finally:
        ctl.shutdown()
        periodic.stop()
        ctl.sensors.stop()


def test_the_watchdog_checks_often_only_while_a_jog_runs(device) -> None:
    """An idle node's housekeeping thread does not wake 4 times per command_timeout to
    find no jog: fast from the first jog, slow again once the dead-man stop ended it."""
    with recorded_periods(device) as (ctl, periodic):
        def periods() -> list[float]:
            return periodic.periods(ctl.watchdog_job.run)

        assert periods() == [WATCHDOG_IDLE_PERIOD_S]
        ctl.command(['pan'], [], [0.5])
        fast = min(0.05, ctl.config.command_timeout / 4)
        assert periods() == [WATCHDOG_IDLE_PERIOD_S, fast]
        ctl.command(['pan'], [], [0.4])  # still jogging: no new period
        assert periods() == [WATCHDOG_IDLE_PERIOD_S, fast]
        wait_for(lambda: ('stop', ['pan']) in device.sent, 5.0, 'the dead-man stop')
        wait_for(lambda: periods()[-1] == WATCHDOG_IDLE_PERIOD_S, 5.0, 'the slow period again')
        assert periods() == [WATCHDOG_IDLE_PERIOD_S, fast, WATCHDOG_IDLE_PERIOD_S]


def test_the_stop_confirmation_looks_often_only_while_a_stop_waits(device) -> None:
    """No stop waiting: every STOP_CHECK_IDLE_S; from the stop (the dead-man stop here) until
    its axis rests: every STOP_CHECK_S; then slow again."""
    with recorded_periods(device) as (ctl, periodic):
        def periods() -> list[float]:
            return periodic.periods(ctl.stop_job.run)

        ctl.command(['pan'], [], [0.5])
        assert periods() == [STOP_CHECK_IDLE_S]  # a jog is no stop
        wait_for(lambda: ('stop', ['pan']) in device.sent, 5.0, 'the dead-man stop')
        wait_for(lambda: ctl.stop_watch.at_rest('pan'), 5.0, 'the axis confirmed at rest')
        wait_for(lambda: periods()[-1] == STOP_CHECK_IDLE_S, 5.0, 'the slow period again')
        assert periods() == [STOP_CHECK_IDLE_S, STOP_CHECK_S, STOP_CHECK_IDLE_S]


def test_a_joint_command_never_waits_for_the_device_reply(controller, device) -> None:
    """The thread rule (ARCHITECTURE.md): a device that waits for ACKs is sent to from the
    command thread; the caller returns while the device is still busy with the send."""
    device.hold_moves = threading.Event()
    caller = threading.Thread(target=controller.command, args=(['pan'], [0.2], []))
    caller.start()
    wait_for(lambda: device.move_threads, 2.0, 'the move reaching the device')
    wait_for(lambda: not caller.is_alive(), 2.0, 'command() returning during the send')
    assert device.move_threads == ['commands']
    device.hold_moves.set()
    wait_for(lambda: controller.commanded_targets.get('pan') == 0.2, 2.0, 'the move sent')


class WriteOnlyDevice(FakeDevice):
    """Moves and jogs that wait for no answer (the turret, Kessler, U-Camera)."""

    def post(self, moves: Moves, jogs: dict[str, float]) -> PostedWrite:
        return self.write_now(moves, jogs)


def running(device: Device):
    """A controller running ``device`` (a fixture body: yields (controller, device))."""
    ctl = GimbalController(device, config(), logging.getLogger('test'))
    ctl.open()
    ctl.activate()
    yield ctl, device
    ctl.shutdown()
    ctl.periodic.stop()
    ctl.sensors.stop()


@pytest.fixture
def write_only():
    yield from running(WriteOnlyDevice())


def test_a_write_only_device_is_sent_to_from_the_callers_thread(write_only) -> None:
    controller, device = write_only
    controller.command(['pan'], [0.2], [])
    assert device.move_threads == [threading.current_thread().name]
    assert controller.commanded_targets == {'pan': 0.2}  # no answer to wait for
    controller.command(['tilt'], [], [0.3])
    assert device.sent[-1] == ('jog', {'tilt': 0.3})  # a jog too, at once


def test_a_write_only_device_behind_a_busy_link_gets_the_newest_from_the_command_thread(
        write_only) -> None:
    controller, device = write_only
    with link_held(controller):  # another send holds the link
        controller.command(['pan'], [0.1], [])
        controller.command(['pan'], [0.2], [])
        assert device.sent == []
    wait_for(lambda: device.sent == [('move', {'pan': (0.2, None)})], 2.0, 'the newest')
    assert device.move_threads == ['commands']


class PostingDevice(FakeDevice):
    """Writes a stream move at once and settles its answers later (Capture, the virtual
    gimbal)."""

    def __init__(self) -> None:
        super().__init__()
        self.can_post = True
        self.settle_error: Exception | None = None
        self.lose_answers = 0  # settles that report a lost answer
        self.post_threads: list[str] = []
        self.finish_threads: list[str] = []  # the thread each settle ran in
        self.settled: list[PostedWrite] = []

    def post(self, moves: Moves, jogs: dict[str, float]) -> PostedWrite | None:
        if not self.can_post or jogs:
            return None
        self.post_threads.append(threading.current_thread().name)
        with self.lock:
            self.sent.append(('post', dict(moves)))
            self.targets.update({joint: target for joint, (target, _) in moves.items()})
        return PostedWrite(dict(moves), {}, replies=2 * len(moves))

    def settle(self, posted: PostedWrite) -> bool:
        self.finish_threads.append(threading.current_thread().name)
        self.settled.append(posted)
        error, self.settle_error = self.settle_error, None
        if error is not None:
            raise error
        if self.lose_answers:
            self.lose_answers -= 1
            return False
        return True


@contextlib.contextmanager
def command_thread_asleep(controller: GimbalController):
    """The command thread does not wake (to settle or send) until the block ends."""
    ready = controller.commands.ready
    controller.commands.ready = threading.Event()
    try:
        yield
    finally:
        controller.commands.ready = ready
        ready.set()


@pytest.fixture
def posting():
    yield from running(PostingDevice())


def test_a_posted_move_is_written_by_the_caller_and_finished_by_the_command_thread(
        posting) -> None:
    controller, device = posting
    controller.command(['pan'], [0.2], [])
    assert device.post_threads == [threading.current_thread().name]
    wait_for(lambda: device.finish_threads == ['commands'], 2.0, 'the replies read')
    wait_for(lambda: controller.commanded_targets.get('pan') == 0.2, 2.0, 'the target')
    assert device.move_threads == []
    assert device.settled[0].replies == 2


def test_the_devices_own_exchange_settles_a_posted_move_first(posting) -> None:
    """The poll (or any request of the device's client) takes the device's link lock,
    which reads the posted write's answers before the poll's own exchange."""
    controller, device = posting
    with command_thread_asleep(controller):
        controller.command(['pan'], [0.2], [])
        assert device.finish_threads == []

        def poll() -> None:
            with device.link_lock:
                pass

        thread = threading.Thread(target=poll, name='poll')
        thread.start()
        thread.join(5.0)
        assert device.finish_threads == ['poll']
        assert controller.commanded_targets.get('pan') == 0.2


def test_a_refusal_in_a_posted_moves_replies_is_counted_and_sets_no_target(posting) -> None:
    controller, device = posting
    device.settle_error = DeviceRefused('device NACK: axis disabled')
    controller.command(['pan'], [0.2], [])
    wait_for(lambda: controller.rejections.counts()['refused'].get(
        'failed on the device: refused by the device'), 2.0, 'the refusal counted')
    assert 'pan' not in controller.commanded_targets
    assert device.move_threads == []  # a refusal is not sent again


def test_a_move_the_device_cannot_post_goes_to_the_command_thread(posting) -> None:
    controller, device = posting
    device.can_post = False
    controller.command(['pan'], [0.2], [])
    wait_for(lambda: device.move_threads == ['commands'], 2.0, 'the move sent')
    controller.command(['tilt'], [], [0.3])  # a jog is never posted
    wait_for(lambda: ('jog', {'tilt': 0.3}) in device.sent, 2.0, 'the jog sent')
    assert device.post_threads == device.finish_threads == []


def test_a_posted_move_whose_answer_was_lost_is_sent_again(posting) -> None:
    controller, device = posting
    device.lose_answers = 1
    controller.command(['pan'], [0.2], [])
    wait_for(lambda: ('move', {'pan': (0.2, None)}) in device.sent, 2.0, 'the resend')
    assert device.move_threads == ['commands']
    assert controller.commanded_targets['pan'] == 0.2
    assert controller.rejections.counts()['refused'] == {}


def test_a_stop_supersedes_a_posted_move_whose_answer_was_lost(posting) -> None:
    """The stop settles the post first (it goes after the send in flight) and nothing
    stale follows it: the lost answer is not sent again."""
    controller, device = posting
    device.lose_answers = 1
    with command_thread_asleep(controller):
        controller.command(['pan'], [0.2], [])
        assert device.sent == [('post', {'pan': (0.2, None)})]
        controller.stop()
        assert device.finish_threads == [threading.current_thread().name]
    assert device.kinds() == ['post', 'stop']
    assert device.move_threads == []
    assert 'pan' not in controller.commanded_targets


def test_a_stops_hold_sends_no_lost_posted_move_before_the_stop(posting) -> None:
    """A stop of pan settles a posted pan + tilt move whose answers were lost: tilt's move
    goes out again, but after the stop, from the command thread; nothing waits for an
    answer under the stop's hold before the stop is written."""
    controller, device = posting
    device.lose_answers = 1
    with command_thread_asleep(controller):
        controller.command(['pan', 'tilt'], [0.2, 0.3], [])
        controller.stop_joints(['pan'])
        assert device.kinds() == ['post', 'stop']
    wait_for(lambda: ('move', {'tilt': (0.3, None)}) in device.sent, 2.0, 'the resend')
    assert device.kinds() == ['post', 'stop', 'move']
    assert device.move_threads == ['commands']


def test_a_newer_queued_move_is_sent_instead_of_a_lost_posted_one(posting) -> None:
    controller, device = posting
    device.lose_answers = 1
    with command_thread_asleep(controller):  # the second comes before the first settles
        controller.command(['pan'], [0.2], [])
        controller.command(['pan'], [0.4], [])
    wait_for(lambda: controller.commanded_targets.get('pan') == 0.4, 2.0, 'the newest')
    assert device.sent == [('post', {'pan': (0.2, None)}), ('move', {'pan': (0.4, None)})]


def test_a_newer_move_keeps_its_target_over_an_unfinished_posted_one(posting) -> None:
    """move_to goes out between the post and the reading of its replies: the posted target
    must not overwrite the newer one when the replies come in."""
    controller, device = posting
    with command_thread_asleep(controller):
        controller.command(['pan'], [0.2], [])
        controller.send_moves({'pan': (0.5, None)})  # settles the post first
    wait_for(lambda: device.finish_threads, 2.0, 'the replies read')
    assert controller.commanded_targets['pan'] == 0.5


def test_a_blocked_sensor_read_does_not_delay_the_dead_man_stop(controller, device) -> None:
    """Sensor jobs (device I/O of a driver's extra topics) run on their own thread: one
    that hangs on a silent device leaves the jog watchdog's thread free."""
    released, entered = threading.Event(), threading.Event()

    def silent_sensor_read() -> None:
        entered.set()
        released.wait()

    controller.sensors.add(0.01, silent_sensor_read)
    try:
        wait_for(entered.is_set, 2.0, 'the sensor read to start')
        controller.command(['pan'], [], [0.5])
        wait_for(lambda: ('stop', ['pan']) in device.sent, 2.0, 'the dead-man stop')
        assert not released.is_set()  # the stop came while the sensor read still hung
    finally:
        released.set()
        controller.sensors.remove(silent_sensor_read)


def test_stop_drops_queued_commands_and_stops_everything(controller, device) -> None:
    with link_held(controller):
        controller.command(['pan'], [0.9], [])
        controller._cancel_motion()  # what stop() does first
    assert controller.stop().startswith('all axes stopped')
    assert 'move' not in device.kinds() and device.sent[-1] == ('stop', None)


def test_moving_rule_prefers_the_device_bit() -> None:
    sample = JointSample({'pan': 0.0}, {'pan': 0.5}, moving={'pan': False})
    assert not is_moving(sample, 'pan')
    assert is_moving(JointSample({'pan': 0.0}, {'pan': 0.01}), 'pan')
    assert not is_moving(JointSample({'pan': 0.0}, {'pan': 1e-4}), 'pan')


def test_axis_state_codes_match_the_message() -> None:
    """AxisStateCode (for ROS-free adapters) mirrors gimbal_msgs/AxisState's constants."""
    from gimbal_driver_common.device import AxisStateCode

    axis_state = pytest.importorskip(
        'gimbal_msgs.msg', reason='needs the built workspace (make build)').AxisState
    for code in AxisStateCode:
        assert getattr(axis_state, f'STATE_{code.name}') == code.value
    assert {n for n in dir(axis_state) if n.startswith('STATE_')} == {
        f'STATE_{code.name}' for code in AxisStateCode}


def test_periodic_trigger_runs_a_job_now_then_on_its_period() -> None:
    from gimbal_driver_common.periodic import Periodic

    periodic = Periodic()
    runs = threading.Semaphore(0)
    try:
        periodic.add(3600.0, runs.release)  # would first run in an hour
        periodic.trigger(runs.release)
        assert runs.acquire(timeout=10.0)
        assert not runs.acquire(timeout=0.2)  # once, then back on its period
    finally:
        periodic.stop()


def test_device_nack_becomes_the_error_with_the_devices_reason(controller, device) -> None:
    device.nack_moves = True
    with pytest.raises(DeviceRefused, match='axis disabled'):
        controller.send_moves({'pan': (0.1, None)})


# ----------------------------------------------------------------- moves
def test_move_reaches_its_target(motion, controller) -> None:
    targets = motion.start_move(['pan', 'tilt'], [0.3, -0.2])
    outcome = motion.wait_move(targets)
    assert outcome.success and outcome.positions == pytest.approx([0.3, -0.2], abs=0.01)


def test_relative_move_resolves_against_the_current_position(motion, controller) -> None:
    motion.wait_move(motion.start_move(['pan'], [0.2]))
    targets = motion.start_move(['pan'], [0.3], relative=True)
    assert targets['pan'] == pytest.approx(0.5, abs=0.02)


def test_move_times_out_and_stops(motion, controller, device) -> None:
    device.step = 0.0001
    controller.config.move_timeout = 0.05
    outcome = motion.wait_move(motion.start_move(['pan'], [0.9]))
    assert outcome.state == 'failed' and 'move_timeout' in outcome.message
    assert device.sent[-1] == ('stop', ['pan'])


def test_move_cancel_stops_the_joints(motion, device) -> None:
    device.step = 0.0001
    outcome = motion.wait_move(motion.start_move(['tilt'], [0.9]), cancelled=lambda: True)
    assert outcome.state == 'cancelled' and device.sent[-1] == ('stop', ['tilt'])


def test_stop_ends_a_running_move(motion, controller, device) -> None:
    device.step = 0.0001
    targets = motion.start_move(['pan'], [0.9])
    threading.Timer(0.05, controller.stop).start()
    assert motion.wait_move(targets).state == 'stopped'


def test_a_stop_between_the_move_and_its_wait_still_ends_it(motion, controller,
                                                             device) -> None:
    """The wait compares against the generation the move's command started, so a stop that
    comes before the wait begins is not missed (it would wait out move_timeout)."""
    device.step = 0.0001
    targets = motion.start_move(['pan'], [0.9])
    controller.stop()
    assert motion.wait_move(targets).state == 'stopped'


def test_a_shutdown_right_after_the_move_ends_it_stopped_not_link_lost(motion, controller,
                                                                       device) -> None:
    """A node that gets SIGINT just after a goal's move went out: the goal says why."""
    device.step = 0.0001
    targets = motion.start_move(['pan'], [0.9])
    controller.shutdown()  # halts, then closes the link, before the goal's wait begins
    outcome = motion.wait_move(targets)
    assert (outcome.state, outcome.message) == ('stopped',
                                                'stopped: the driver is shutting down')


def test_move_refusals_send_nothing(motion, device) -> None:
    with pytest.raises(InvalidRequest, match='velocity_max'):
        motion.start_move(['pan'], [0.1], [5.0])
    with pytest.raises(InvalidRequest):
        motion.start_move(['pan'], [0.1], [0.1, 0.2])
    device.refuse = 'tilt faulted'
    with pytest.raises(DeviceRefused, match='tilt faulted'):
        motion.start_move(['tilt'], [0.1])
    assert device.kinds() == []


# ----------------------------------------------------------------- homing
def test_home_without_the_capability_says_so(motion) -> None:
    with pytest.raises(Unsupported, match='no homing'):
        motion.home([], lambda state: None)


def test_home_runs_the_device_routine(motion, device) -> None:
    device.capabilities.homing = FakeHoming(device)
    device.positions['pan'] = 0.3
    states = []
    assert motion.home(['pan'], states.append) == 'homed'
    with pytest.raises(InvalidRequest, match='unknown joint'):
        motion.home(['roll'], states.append)


def _home_in_thread(motion, homing: WaitingHoming, cancel_requested=lambda: False):
    """Start a homing with ``homing`` in a thread; return once it waits in the device."""
    ended: dict = {}

    def run() -> None:
        try:
            ended['answer'] = motion.home(['pan'], lambda state: None, cancel_requested)
        except Exception as exc:  # noqa: BLE001 - the test reads it
            ended['error'] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    wait_for(lambda: homing.cancelled is not None, 2.0, 'the homing to wait in the device')
    return thread, ended


def test_a_cancel_request_ends_a_homing_that_only_waits(motion, device) -> None:
    """The cancel reaches the device's wait even when the routine never reports again."""
    device.capabilities.homing = homing = WaitingHoming()
    requested = threading.Event()
    thread, ended = _home_in_thread(motion, homing, requested.is_set)
    requested.set()
    thread.join(5.0)
    assert not thread.is_alive() and homing.cancelled.is_set()
    assert str(ended.get('error')) == 'homing cancelled'  # the action layer stops the axes


@pytest.mark.parametrize('newer', ['stop', 'move'])
def test_a_newer_motion_command_supersedes_a_homing(motion, controller, device,
                                                    newer) -> None:
    device.capabilities.homing = homing = WaitingHoming()
    thread, ended = _home_in_thread(motion, homing)
    if newer == 'stop':
        controller.stop()
    else:
        motion.start_move(['pan'], [0.2])
    thread.join(5.0)
    assert not thread.is_alive() and homing.cancelled.is_set()
    assert isinstance(ended.get('error'), HomingSuperseded)
    if newer == 'move':  # nothing after the newer move: the homing sent no stop
        assert device.kinds()[-1] == 'move'


# ------------------------------------------------------------------ scans
def test_driver_side_scan_moves_then_stops(motion, controller, device) -> None:
    message = motion.start_scan(ScanRequest('sector', -0.2, 0.2, 0.0, 0.0, 1.0, 0.0, 0.0))
    assert 'driver-side' in message
    wait_for(lambda: device.kinds().count('move') >= 2, 2.0, 'two scan waypoints')
    assert motion.stop_scan() == 'scan stopped'
    wait_for(lambda: not motion.scanning, 2.0, 'the scan thread to end')


def test_unknown_scan_pattern_is_refused(motion, device) -> None:
    with pytest.raises(InvalidRequest, match='pattern'):
        motion.start_scan(ScanRequest('spiral', -0.2, 0.2, 0.0, 0.0, 1.0, 0.0, 0.0))
    assert device.kinds() == []


def test_device_scan_is_used_for_its_patterns_and_stopped_by_stop(motion, controller,
                                                                   device) -> None:
    scans = device.capabilities.scans = FakeScans()
    assert motion.start_scan(ScanRequest('spiral', -0.2, 0.2, 0, 0, 1.0, 0, 0)) == 'device spiral'
    controller.stop()
    assert not scans.running


# ---------------------------------------------------------------- presets
def test_yaml_presets_set_goto_list_clear(motion, controller) -> None:
    motion.set_preset(3, 'door', {'pan': 0.4, 'tilt': 0.1})
    assert [p.name for p in motion.list_presets()] == ['door']
    assert 'preset 3' in motion.goto_preset(3, 0.0)
    wait_for(lambda: abs(controller.positions()['pan'] - 0.4) < 1e-9, 2.0, 'the preset move')
    motion.clear_preset(3)
    with pytest.raises(InvalidRequest):
        motion.goto_preset(3, 0.0)


def test_device_slot_composes_with_the_yaml_store(motion, device) -> None:
    device.capabilities.presets = SlotZeroPresets()
    assert motion.set_preset(0, 'home', {'pan': 0.0, 'tilt': 0.0}) == 'stored on the device'
    assert motion.set_preset(1, 'gate', {'pan': 0.5, 'tilt': 0.0}).startswith('preset 1 stored')
    assert [(p.index, p.name) for p in motion.list_presets()] == [(0, 'home'), (1, 'gate')]
    assert motion.goto_preset(0, 0.0) == 'device moving to slot 0'
    assert motion.clear_preset(None) == 'all presets cleared'
    assert motion.list_presets() == []


def test_device_slot_target_becomes_the_commanded_target(motion, controller, device) -> None:
    """A device slot that knows where it leads (DevicePresets.target) sets target_position."""

    class KnownSlot(SlotZeroPresets):
        def target(self, index):
            return dict(self.slot[1]) if self.slot else None

    device.capabilities.presets = SlotZeroPresets()
    motion.set_preset(0, 'home', {'pan': 0.3, 'tilt': 0.1})
    motion.goto_preset(0, 0.0)
    assert 'pan' not in controller.commanded_targets  # target unknown: left alone
    device.capabilities.presets = known = KnownSlot()
    known.slot = ('home', {'pan': 0.3, 'tilt': 0.1})
    motion.goto_preset(0, 0.0)
    assert controller.commanded_targets == {'pan': 0.3, 'tilt': 0.1}


def test_preset_refusals(motion, device) -> None:
    with pytest.raises(InvalidRequest):
        motion.set_preset(1, 'x', {'pan': 9.0})
    with pytest.raises(InvalidRequest, match='speed'):
        motion.goto_preset(1, -1.0)
    motion.set_preset(1, 'x', {'pan': 0.1})
    device.refuse = 'pan is off'
    with pytest.raises(DeviceRefused, match='pan is off'):
        motion.goto_preset(1, 0.0)
    assert device.kinds() == []


def test_set_preset_from_the_current_position(motion, controller) -> None:
    motion.wait_move(motion.start_move(['pan'], [0.25]))
    motion.set_preset(2, 'here', None)
    assert motion.list_presets()[0].positions['pan'] == pytest.approx(0.25, abs=0.01)


# --------------------------------------------------------------- lifecycle
def test_deactivate_stops_the_axes_and_refuses_commands(controller, device) -> None:
    controller.deactivate()
    assert device.sent[-1] == ('stop', None)
    assert controller.refusal() is not None


def test_a_new_move_supersedes_a_waiting_move(motion, controller, device) -> None:
    device.step = 0.0001
    targets = motion.start_move(['pan'], [0.9])
    threading.Timer(0.05, lambda: motion.start_move(['tilt'], [0.1])).start()
    assert motion.wait_move(targets).state == 'stopped'


def test_joint_command_ends_a_driver_side_scan(motion, controller) -> None:
    motion.start_scan(ScanRequest('sector', -0.2, 0.2, 0.0, 0.0, 1.0, 0.0, 0.0))
    controller.command(['pan'], [0.0], [])
    wait_for(lambda: not motion.scanning, 2.0, 'the scan thread to end')


def test_a_device_reports_its_own_targets_through_the_contract(controller, device) -> None:
    """A device-run motion (a device preset, a geo-pointing) reports its targets with
    ``Device.report_targets``; the controller records them (AxisState.target_position)."""
    reported = {'pan': 0.4}
    device.report_targets(reported)
    reported['pan'] = 9.0  # the controller keeps its own copy
    assert controller.commanded_targets == {'pan': 0.4}



# ------------------------------------------- a new motion command drops the queue
class LinkedRoutines(Homing, DevicePresets, DeviceScans):
    """Homing, a device preset slot and a device scan that each take the link lock for
    their exchange and record it, as a request/reply client does."""

    patterns = ('spiral',)

    def __init__(self, device: FakeDevice) -> None:
        self.device = device

    def _exchange(self, what: str) -> str:
        with self.device.link_lock, self.device.lock:
            self.device.sent.append((what, None))
        return what

    def home(self, joints, report, cancelled) -> str:
        return self._exchange('home')

    def handles(self, index: int) -> bool:
        return index == 0

    def set(self, index, name, positions) -> str:
        return 'stored'

    def goto(self, index, speed) -> str:
        return self._exchange('preset')

    def list(self):
        return []

    def clear(self, index) -> str:
        return 'cleared'

    def start(self, request: ScanRequest) -> str:
        return self._exchange('scan')

    def stop(self) -> None:
        self._exchange('scan stop')


NEWER_COMMANDS = {
    'move_to': lambda motion, ctl: motion.start_move(['pan'], [-0.2]),
    'home': lambda motion, ctl: motion.home(['pan'], lambda state: None),
    'device preset': lambda motion, ctl: motion.goto_preset(0, 0.0),
    'yaml preset': lambda motion, ctl: motion.goto_preset(4, 0.0),
    'device scan': lambda motion, ctl: motion.start_scan(
        ScanRequest('spiral', -0.2, 0.2, 0, 0, 1.0, 0, 0)),
    'driver scan': lambda motion, ctl: motion.start_scan(
        ScanRequest('sector', -0.2, 0.2, 0.0, 0.0, 1.0, 0.0, 0.0)),
    '~/stop': lambda motion, ctl: ctl.stop(),
}


@pytest.mark.parametrize('newer', list(NEWER_COMMANDS))
def test_a_new_motion_command_drops_the_joint_commands_queued_before_it(
        motion, controller, device, newer) -> None:
    """Issue 39 item 4: joint_commands queued behind a busy link (a move for one joint, a
    jog for the other) never reach the device after a newer motion command."""
    routines = LinkedRoutines(device)
    device.capabilities.homing = routines
    device.capabilities.presets = routines
    device.capabilities.scans = routines
    motion.set_preset(4, 'yaml slot', {'pan': -0.2, 'tilt': 0.0})
    ended = threading.Event()
    with link_held(controller):  # a read in flight: both commands wait in the queue
        controller.command(['pan'], [0.5], [])
        controller.command(['tilt'], [], [0.3])
        generation = controller.motion_generation
        caller = threading.Thread(
            target=lambda: (NEWER_COMMANDS[newer](motion, controller), ended.set()),
            daemon=True)
        caller.start()
        # the newer command has superseded what came before; its own send waits for
        # the link like everything else
        wait_for(lambda: controller.motion_generation != generation, 2.0, 'the preemption')
    assert ended.wait(5.0), f'{newer} did not return'
    wait_for(lambda: len(device.sent) >= 1, 2.0, 'the newer command on the link')
    motion.stop_scan() if newer == 'driver scan' else None
    with device.lock:
        sent = list(device.sent)
    assert ('move', {'pan': (0.5, None)}) not in sent, sent
    assert ('jog', {'tilt': 0.3}) not in sent, sent


@pytest.mark.parametrize('stop', ['~/stop', 'dead-man'])
def test_a_stop_goes_ahead_of_the_reads_queued_for_the_link(controller, device, stop) -> None:
    """Issue 39 item 2: while one exchange is in flight and reads wait for the link (a
    sensor, a status register), a stop is the next thing on the link."""
    if stop == 'dead-man':
        controller.command(['pan'], [], [0.5])
        wait_for(lambda: ('jog', {'pan': 0.5}) in device.sent, 2.0, 'the jog')
    waiting = []

    def queued_read(name: str) -> None:
        waiting.append(name)
        with device.link_lock, device.lock:
            device.sent.append(('read', name))

    with link_held(controller):
        readers = [threading.Thread(target=queued_read, args=(name,), daemon=True)
                   for name in ('imu', 'registers')]
        for reader in readers:
            reader.start()
        wait_for(lambda: len(waiting) == 2, 2.0, 'two reads waiting for the link')
        if stop == '~/stop':
            stopper = threading.Thread(target=controller.stop, daemon=True)
            stopper.start()
        wait_for(lambda: controller.commands.link_lock.waiting(urgent=True) == 1, 5.0,
                 'the stop queued')
    for reader in readers:
        reader.join(5.0)
    wait_for(lambda: device.kinds().count('read') == 2, 2.0, 'both reads done')
    kinds = [kind for kind in device.kinds() if kind in ('stop', 'read')]
    assert kinds[0] == 'stop', device.sent


def test_periodic_jobs_whose_periods_divide_each_other_share_wake_ups() -> None:
    """After each job's first run, jobs run on a common grid: the thread wakes as often
    as its fastest job, not once per job (each wake-up costs about what a quick job
    does). A late thread only merges more runs into one wake-up."""
    from gimbal_driver_common.periodic import Periodic

    periodic = Periodic()
    fast_runs = threading.Semaphore(0)
    try:
        periodic.add(0.02, fast_runs.release)
        periodic.add(0.04, lambda: None)
        periodic.add(lambda: 0.08, lambda: None)  # a period read at each run
        for _ in range(30):
            assert fast_runs.acquire(timeout=10.0)
        # each job's first run is one period after add, off the grid: up to 2 extra
        assert periodic.wakeups <= 30 + 2 + 1
    finally:
        periodic.stop()


def test_next_on_grid_is_the_next_multiple_of_the_period() -> None:
    from gimbal_driver_common.periodic import next_on_grid

    assert next_on_grid(0.5, 10.2) == pytest.approx(10.5)
    assert next_on_grid(0.5, 10.5) == pytest.approx(11.0)  # later than, not at
    assert next_on_grid(0.1, 0.0) == pytest.approx(0.1)
