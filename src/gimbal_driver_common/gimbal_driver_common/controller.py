"""The controller: everything every driver does the same way, with no ROS in it.

It owns the device thread (poll or stream, then hand each sample to the node),
the one connection supervisor (open, identity, reconnect every
``reconnect_period``, link state with reason and count), the command thread
(newest command per joint wins, sent before the next poll), the jog dead-man
watchdog, ``stop`` and the refusal rules.

The thread rule: :meth:`GimbalController.command` (the joint_command callback) never
waits for a device reply. It validates and hands the command to the one command path
(:mod:`gimbal_driver_common.command_path`), which posts what the device can write at
once and leaves answers, resends and everything else to the command thread.
Periodic work runs on two plain threads: ``periodic`` (housekeeping: the jog
watchdog, diagnostics, ~/status, all quick) and ``sensors`` (the driver's extra topics
that read the device), so a slow or silent sensor read never delays a dead-man stop.
Moves, homing, scans and presets are policies in :mod:`gimbal_driver_common.policies`
built on this class.

The ROS node is an adapter around one controller (see ``ros/base_node.py``),
like ros2_canopen's node around its driver object; the controller is
unit-tested against a fake device in ``test/test_controller.py``.
"""

from __future__ import annotations

import enum
import math
import threading
import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import TypeVar

from gimbal_driver_common.command_path import CommandPath
from gimbal_driver_common.config import ControllerConfig, Logger
from gimbal_driver_common.device import Device, DeviceInfo, JointSample, Moves
from gimbal_driver_common.errors import DeviceRefused, GimbalError, LinkError, device_boundary
from gimbal_driver_common.joint_command import validate_joint_command
from gimbal_driver_common.motion_watch import MotionWatch
from gimbal_driver_common.periodic import PacedJob, Period, Periodic
from gimbal_driver_common.rejections import CommandRejections
from gimbal_driver_common.stopping import STOP_CHECK_IDLE_S, STOP_CHECK_S, Stopping
from gimbal_driver_common.streamed_samples import StreamedSamples
from gimbal_driver_common.watchdog import JogWatchdog

T = TypeVar('T')
__all__ = ['STOP_CHECK_IDLE_S', 'STOP_CHECK_S', 'ControllerConfig', 'GimbalController',
           'LinkState', 'Logger', 'is_moving']

#: a joint without a device "moving" bit is moving when faster than this (rad/s or m/s)
MOVING_SPEED = 1e-3
#: longest a streamed device's thread waits for data before checking the link again
STREAM_WAIT_S = 0.05
#: how often the jog watchdog checks while no joint jogs (or it is disabled)
WATCHDOG_IDLE_PERIOD_S = 0.5


class LinkState(enum.Enum):
    """Where the connection supervisor is; ``GimbalController.link_error`` says why."""

    NOT_CONFIGURED = 'not configured'   # never opened (or closed by cleanup)
    CONNECTED = 'connected'
    LOST = 'lost'                       # dropped while connected; reconnecting next
    RECONNECTING = 'reconnecting'       # a reconnect attempt failed; trying again


def is_moving(sample: JointSample | None, joint: str) -> bool:
    """The one "moving" rule: the device's own bit where it has one, else the speed."""
    if sample is None:
        return False
    if joint in sample.moving:
        return bool(sample.moving[joint])
    return abs(sample.velocities.get(joint, 0.0)) > MOVING_SPEED


class GimbalController:
    """Runs one :class:`Device`; thread-safe; every public method answers or raises GimbalError."""

    def __init__(
        self, device: Device, config: ControllerConfig, log: Logger,
        on_sample: Callable[[JointSample], None] | None = None,
        on_link_change: Callable[[], None] | None = None, periodic: Periodic | None = None,
        sensors: Periodic | None = None,
        rejections: CommandRejections | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``clock`` times the jog watchdog and the stop confirmation (tests inject one)."""
        self.device = device
        self.clock = clock
        self.config = config
        self.log = log
        device.attach(config, log, self._show_targets)
        self.on_sample = on_sample or (lambda sample: None)
        self.on_link_change = on_link_change or (lambda: None)
        self.device_info = DeviceInfo()
        self.link_state = LinkState.NOT_CONFIGURED
        self.active = False
        #: why the link is not connected, for people ('' while connected)
        self.link_error = 'not configured'
        self.reconnects = 0
        self.latest: JointSample | None = None
        #: last position target sent per joint (AxisState.target_position); changed only
        #: through :meth:`record_targets`
        self.commanded_targets: dict[str, float] = {}
        #: accepted commands that show no motion (motion_start_timeout): diagnostics, goals
        self.motion_watch = MotionWatch(lambda: self.config.motion_start_timeout,
                                        lambda: self.config.goal_tolerance, log)
        self._targets_lock = threading.Lock()
        #: bumped by every stop and halt (:meth:`bump_motion_generation`): a running move
        #: or scan sees it and ends
        self.motion_generation = 0
        #: :meth:`shutdown` began: what a move that ends now was stopped by
        self.shutting_down = False
        self._generation_lock = threading.Lock()
        self.periodic = periodic or Periodic(on_error=log.error)
        #: jobs that do device I/O (sensor topics): never on the watchdog's thread
        self.sensors = sensors or Periodic(on_error=log.error, name='sensors')
        #: refused joint_commands, counted and logged by reason (the node keeps one across
        #: configure/cleanup and passes it in)
        self.rejections = rejections or CommandRejections(log)
        self.halt_hooks: list[Callable[[], None]] = []  # stop and halt call these first (policies)
        self.preempt_hooks: list[Callable[[], None]] = []  # a joint_command calls these
        self.commands = CommandPath(device, self.rejections, self.record_targets,
                                    self._send_refusal, self.motion_watch.jogged)
        #: every stop, and its confirmation by the axes (:mod:`~.stopping`)
        self.stops = Stopping(device, config, log, self.commands, self.motion_watch,
                              self.periodic, is_moving, lambda: self.connected,
                              self._throttle, clock)
        #: stops not yet confirmed by the axis (stop_deceleration, stop_margin): resent
        #: from the housekeeping thread until the axis is at rest; diagnostics, ~/stop
        self.stop_watch = self.stops.watch
        #: the stop confirmation: runs often only while a stop waits (:class:`PacedJob`)
        self.stop_job = self.stops.job
        self.watchdog = JogWatchdog(config.command_timeout, self._on_jog_expired, clock=clock,
                                    settled=self.stop_watch.at_rest)
        #: the watchdog's check: runs often only while a joint jogs
        self.watchdog_job = PacedJob(self.periodic, self.watchdog.check,
                                     lambda: bool(self.watchdog.jogging),
                                     self._watchdog_period, WATCHDOG_IDLE_PERIOD_S)
        self._stopping = threading.Event()
        self._wake = threading.Event()
        self._threads: list[threading.Thread] = []
        self._warned: dict[str, float] = {}
        #: the device's background reads as the sensors thread runs them
        self._background: list[tuple[Period, Callable[[], None]]] = []
        #: a streamed device's samples, taken on its receive thread
        self.streamed_samples = StreamedSamples(
            device, self._take_sample,
            lambda: self.connected and not self._stopping.is_set(),
            lambda: 1.0 / self.config.publish_rate, clock)
        if device.streamed:
            device.on_stream_data(self.streamed_samples.on_data)

    @property
    def connected(self) -> bool:
        return self.link_state is LinkState.CONNECTED

    # ----------------------------------------------------------- lifecycle
    def open(self) -> None:
        """Open the link and start the device and command threads (lifecycle configure),
        and the device's background reads on the sensors thread."""
        self._connect()
        self._background = [(period, self._background_job(job))
                            for period, job in self.device.background_reads()]
        for period, job in self._background:
            self.sensors.add(period, job)
        self.device.on_background_wake(self._run_background_now)
        self._run_background_now()
        self._stopping.clear()
        self.commands.reopen()
        self._threads = [
            threading.Thread(target=self._device_loop, name='device', daemon=True),
            threading.Thread(target=self.commands.run, name='commands', daemon=True),
        ]
        for thread in self._threads:
            thread.start()

    def activate(self) -> None:
        self.active = True

    def deactivate(self, why: str = 'deactivating') -> None:
        self.halt(why)
        self.active = False

    def close(self) -> None:
        """Stop the threads and close the link (cleanup, shutdown)."""
        self._stopping.set()
        self._wake.set()
        self.commands.close()
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(timeout=5.0)
        self._threads = []
        if self.link_state is LinkState.CONNECTED:
            self.link_error = 'link closed (lifecycle cleanup)'
        # else the reason it is not connected (say, why configure failed) stays readable
        self._close_device()
        self.link_state = LinkState.NOT_CONFIGURED
        self.watchdog_job.remove()
        self.stop_job.remove()
        for _, job in self._background:
            self.sensors.remove(job)
        self._background = []

    def shutdown(self, why: str = 'shutting down') -> None:
        """Stop what this driver was moving, then close."""
        self.shutting_down = True  # before the halt: the goals it ends say why
        if self.active:
            self.halt(why)
            self.stops.confirm_before_close(why)
        self.active = False
        self.close()

    def halt(self, why: str) -> None:
        """Stop every axis and everything that would move it again."""
        self._cancel_motion()
        if not self.connected:
            return
        try:
            self.stops.send(None)
            self.log.info(f'{why}: stop sent to every axis')
        except GimbalError as exc:
            self.log.error(f'{why}: stopping the axes failed: {exc}')

    # ---------------------------------------------------------- parameters
    def set_publish_rate(self, rate: float) -> None:
        self.config.publish_rate = rate
        self._wake.set()  # the device thread picks up the new period now

    def set_command_timeout(self, timeout: float) -> None:
        self.config.command_timeout = timeout
        self.watchdog.timeout_s = timeout
        self.watchdog_job.repace()

    def _watchdog_period(self) -> float:
        """Check jogs 4 times per timeout (at least every 50 ms) while a jog runs; 0 (the
        idle period) with the watchdog disabled."""
        timeout = self.config.command_timeout
        return min(0.05, timeout / 4) if timeout > 0 else 0.0

    # ------------------------------------------------------------- refusals
    def refusal(self, joints: Sequence[str] | None = None) -> str | None:
        """Why a command cannot be served now, or None; with ``joints``: why they cannot move."""
        refused = self._refusal(joints)
        return refused[1] if refused else None

    def _refusal(self, joints: Sequence[str] | None) -> tuple[str, str] | None:
        """(reason without details, message) of :meth:`refusal`, or None."""
        if not self.active:
            return 'node not active', 'node is not active (lifecycle); activate it first'
        if not self.connected:
            return 'device not connected', f'device not connected ({self.link_error})'
        message = self.device.refusal(list(joints)) if joints else None
        return ('the device cannot move the axes', message) if message else None

    def require(self, joints: Sequence[str] | None = None) -> None:
        """Raise :class:`DeviceRefused` with :meth:`refusal`'s reason, if there is one."""
        refused = self._refusal(joints)
        if refused:
            raise DeviceRefused(refused[1], reason=refused[0])

    def call(self, request: Callable[[], T], joints: Sequence[str] | None = None) -> T:
        """Run a device request from a service: refused while it cannot be served, and
        every failure comes out as a GimbalError (the one boundary for driver extras)."""
        self.require(joints)
        with device_boundary():
            return request()

    def moving(self, joint: str) -> bool:
        return is_moving(self.latest, joint)

    def busy(self) -> str | None:
        """Why the axes are not idle (jogging, moving), or None: for parameters that may
        only change while nothing moves, such as unit scales."""
        jogging = self.watchdog.jogging
        if jogging:
            return f'jogging {jogging}'
        moving = [n for n in self.config.joint_names if self.moving(n)]
        return f'moving {moving}' if moving else None

    def positions(self) -> dict[str, float]:
        sample = self.latest
        return dict(sample.positions) if sample else {}

    # ------------------------------------------------------------- commands
    def command(
        self, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float]
    ) -> None:
        """A joint_command: validated, then queued for the command thread (newest per
        joint wins); a device that sends without waiting for a reply gets it from this
        thread at once when the link is free. The caller never waits for a device reply
        nor behind another send. Raises (nothing sent) when the command is invalid or the
        axes cannot move. A joint with NaN has no command and is left alone; a command
        with nothing but NaN does nothing (not even refused).
        """
        plan = validate_joint_command(names, positions, velocities, self.config.limits)
        if plan.empty:
            return
        movers = list(plan.moves) + [j for j, v in plan.jogs.items() if v != 0.0]
        self.require(movers or None)  # active and connected; and the movers can move
        for hook in self.preempt_hooks:
            hook()
        self.watchdog.cancel(list(plan.moves) + [j for j, v in plan.jogs.items() if v == 0.0])
        jogs = [j for j, v in plan.jogs.items() if v != 0.0]
        if jogs:
            self.watchdog.feed(jogs)
            self.watchdog_job.pace()
        self.stop_watch.superseded(movers)
        self.commands.submit(plan.moves, plan.jogs)

    def _send_refusal(self) -> str | None:
        """Why the command path cannot send now (the link dropped), or None."""
        return None if self.connected else f'device not connected ({self.link_error})'

    def record_targets(self, targets: dict[str, float]) -> None:
        """Position targets sent (by the command path, or by a policy through a device
        capability): ~/status shows them and the motion watch waits for motion."""
        self._show_targets(targets)
        self.stop_watch.superseded(targets)
        self.motion_watch.commanded(targets)

    def _show_targets(self, targets: dict[str, float]) -> None:
        """Targets for ~/status only: also what the device reports it took by itself
        (``Device.report_targets``: levelling, new units), which the watch leaves alone."""
        with self._targets_lock:
            self.commanded_targets.update(targets)

    def bump_motion_generation(self) -> int:
        """End a running move or scan (they compare :attr:`motion_generation`); returns the
        new generation, the one a command that preempts with this bump runs in."""
        with self._generation_lock:
            self.motion_generation += 1
            return self.motion_generation

    def send_moves(self, moves: Moves, offsets: dict[str, float] | None = None) -> None:
        """Send absolute moves now (move_to, presets, scans), after the queued commands."""
        self.watchdog.cancel(list(moves))

        def send() -> None:
            if not (offsets and self.device.move_relative(offsets, moves)):
                self.device.move(moves)

        self.commands.send(list(moves), send)
        self.record_targets({joint: move[0] for joint, move in moves.items()})

    def stop(self) -> str:
        """~/stop: cancel jogs, moves, scans and queued commands, stop every axis and
        answer once every axis is at rest (:meth:`Stopping.stop_all`)."""
        self._cancel_motion()
        self.require_connected('nothing to stop')
        return self.stops.stop_all()

    def stop_joints(self, joints: Sequence[str] | None) -> None:
        """Stop some joints (a cancelled move or homing, the dead-man stop); logs instead
        of raising: the stop watch sends it again until the axes rest."""
        self.stops.send_logged(joints)

    def confirm_stops(self) -> None:
        """Housekeeping: send the stop again to the axes still moving past their time."""
        self.stops.confirm()

    def require_connected(self, what: str) -> None:
        if not self.connected:
            raise LinkError(f'device not connected ({self.link_error}); {what}')

    def reset_faults(self) -> str:
        return self.call(self.device.reset_faults)

    def _cancel_motion(self) -> None:
        self.watchdog.cancel()
        self.motion_watch.withdraw()
        self.commands.drop(None)
        # the policies learn of the halt before the generation moves on: a procedure that
        # sees the new generation then knows it was a stop, not a newer command
        for hook in self.halt_hooks:
            hook()
        self.bump_motion_generation()

    def _on_jog_expired(self, joints: list[str]) -> None:
        self.log.warning(
            f'jog of {joints} expired (no joint_command for '
            f'{self.config.command_timeout:g} s): stopping')
        if self.connected:
            self.stop_joints(joints)

    # ------------------------------------------------------ device thread
    def _device_loop(self) -> None:
        """Supervise the link; poll at publish_rate (a streamed device's samples are taken
        on its receive thread: :mod:`~.streamed_samples`)."""
        next_tick = time.monotonic()
        while not self._stopping.is_set():
            period = 1.0 / self.config.publish_rate
            if not self.connected:
                self._reconnect()
                next_tick = time.monotonic()
                continue
            if self.device.streamed:
                # woken because the receive thread declined (a sample too soon, the link
                # down, a read raised), or the stream was quiet: take it here once due,
                # where a lost link is handled
                if not self.streamed_samples.wait(STREAM_WAIT_S):
                    continue
                hold = self.streamed_samples.hold()
                if hold > 0 and self._sleep(hold):
                    continue
                try:
                    self.streamed_samples.take()
                except GimbalError as exc:
                    self._on_link_lost(exc)
                continue
            try:
                with device_boundary():
                    if not self.device.link_healthy():
                        raise LinkError('the client reports its link is down')
                    read_at = self.clock()
                    sample = None
                    if not self.device.request_read(partial(self._take_sample,
                                                            read_at=read_at)):
                        sample = self.device.read()
            except GimbalError as exc:
                self._on_link_lost(exc)
                continue
            if sample is not None:
                self._take_sample(sample, read_at)
            next_tick += period
            delay = next_tick - time.monotonic()
            if delay < -period:  # fell behind (slow device): do not burst to catch up
                next_tick, delay = time.monotonic(), 0.0
            self._sleep(max(delay, 0.0))

    def _take_sample(self, sample: JointSample, read_at: float) -> bool:
        """A new sample, read from ``read_at`` on: the watches see it, the node publishes it
        while active (True). On the device thread, or on the link's reader thread for a
        device that polls without waiting (:meth:`Device.request_read`) or streams
        (:mod:`~.streamed_samples`, under its lock): samples are taken in order."""
        self.latest = sample
        self.motion_watch.observe(sample)
        self.stop_watch.observe(sample, read_at)
        if not self.active:
            return False
        self.on_sample(sample)
        return True

    def _sleep(self, timeout: float) -> bool:
        """Sleep up to ``timeout``; True when woken early (stopping or publish_rate changed)."""
        woken = self._wake.wait(timeout)
        if woken and not self._stopping.is_set():
            self._wake.clear()
        return woken

    def _run_background_now(self) -> None:
        for _, job in self._background:
            self.sensors.trigger(job)

    def _background_job(self, job: Callable[[], None]) -> Callable[[], None]:
        """``job`` run only while connected; a device error is logged (at most every 10 s
        per kind), a lost link is the device thread's to notice."""

        def run() -> None:
            if not self.connected:
                return
            try:
                with device_boundary():
                    job()
            except LinkError:
                return
            except GimbalError as exc:
                if self._throttle(f'background {type(exc).__name__}', 10.0):
                    self.log.warning(f'background read: {exc}')

        return run

    def _connect(self, reconnect: bool = False) -> None:
        try:
            with device_boundary():
                info = self.device.open()
        except GimbalError as exc:
            self._close_device()
            self.link_error = str(exc)
            raise
        self.device_info = info if isinstance(info, DeviceInfo) else DeviceInfo()
        if reconnect:  # counted before the state says connected: the two are read together
            self.reconnects += 1
        self.link_state, self.link_error = LinkState.CONNECTED, ''
        self._run_background_now()  # what a new connection reads, read first
        self.log.info(
            f'connected to {self.device_info.model or "device"} '
            f'(serial {self.device_info.serial_number or "?"}, '
            f'firmware {self.device_info.firmware_version or "?"})')

    def _close_device(self) -> None:
        """Close the device link; the caller sets the state it leaves the link in."""
        try:
            self.device.close()
        except Exception as exc:  # noqa: BLE001 - closing must never raise out
            self.log.warning(f'closing the device link: {exc}')

    def _on_link_lost(self, exc: BaseException) -> None:
        self.link_state, self.link_error = LinkState.LOST, f'link lost: {exc}'
        self.watchdog.cancel()
        self.log.error(
            f'device link lost ({exc}); reconnecting every {self.config.reconnect_period:g} s')
        self.on_link_change()
        self._close_device()

    def _reconnect(self) -> None:
        if self._stopping.wait(self.config.reconnect_period):
            return
        try:
            self._connect(reconnect=True)
        except GimbalError as exc:
            self.link_state, self.link_error = LinkState.RECONNECTING, f'reconnecting: {exc}'
            if self._throttle('reconnect', 10.0):
                self.log.warning(f'reconnect failed: {exc}')
            return
        self.log.info(f'reconnected (reconnect #{self.reconnects})')
        self.on_link_change()

    def _throttle(self, key: str, period: float) -> bool:
        """True at most once per ``period`` s per key (for repeated log lines)."""
        now = time.monotonic()
        if now - self._warned.get(key, -math.inf) < period:
            return False
        self._warned[key] = now
        return True
