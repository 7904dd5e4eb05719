"""Every stop of the controller, and its confirmation by the axes (no ROS).

A part of :class:`~gimbal_driver_common.controller.GimbalController` (its ``stops``),
kept apart so each reads in one sitting. It writes every step of a stop (the device's
motion first, then its scans; a failed step skips no other), tells the
:class:`~gimbal_driver_common.stop_watch.StopWatch` what was stopped, sends the whole stop
again from the housekeeping thread while an axis moves past its deceleration time, and
lets ``~/stop`` and a shutdown wait, woken by samples, for the axes to rest.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from gimbal_driver_common.command_path import CommandPath
from gimbal_driver_common.config import ControllerConfig, Logger
from gimbal_driver_common.device import Device, JointSample
from gimbal_driver_common.errors import DeviceRefused, EverySteps, GimbalError
from gimbal_driver_common.motion_watch import MotionWatch
from gimbal_driver_common.periodic import PacedJob, Periodic
from gimbal_driver_common.stop_watch import StopWatch

#: s between two looks of the housekeeping thread at the stops not yet confirmed
STOP_CHECK_S = 0.05
#: s between two looks while no stop waits (the first stop switches to STOP_CHECK_S)
STOP_CHECK_IDLE_S = 0.5
#: s a shutdown waits beyond the deceleration time for the axes to rest before closing
SHUTDOWN_CONFIRM_S = 1.0


class Stopping:
    """Sends stops and keeps sending them until the axes confirm (thread-safe)."""

    def __init__(self, device: Device, config: ControllerConfig, log: Logger,
                 commands: CommandPath, motion_watch: MotionWatch, periodic: Periodic,
                 moving: Callable[[JointSample | None, str], bool],
                 connected: Callable[[], bool], throttle: Callable[[str, float], bool],
                 clock: Callable[[], float]) -> None:
        """``connected`` and ``throttle`` are the controller's (link state, log pacing)."""
        self.device = device
        self.config = config
        self.log = log
        self.commands = commands
        self.motion_watch = motion_watch
        self.connected = connected
        self.throttle = throttle
        #: stops not yet confirmed by the axis (stop_deceleration, stop_margin):
        #: diagnostics, ~/stop
        self.watch = StopWatch(lambda: config.stop_deceleration,
                               lambda: config.stop_margin, moving, log, clock=clock)
        #: the confirmation looks often only while a stop waits
        self.job = PacedJob(periodic, self.confirm, self.watch.waiting,
                            lambda: STOP_CHECK_S, STOP_CHECK_IDLE_S)

    def send(self, joints: Sequence[str] | None) -> None:
        """Write every step of the stop, device motion first, then its scans; a step that
        fails skips no other. Raises after all were sent, with every failure."""
        steps = EverySteps()
        device = self.device

        def send() -> None:
            steps.run(device.stop, None if joints is None else list(joints))
            scans = device.capabilities.scans
            if scans is not None and joints is None and not scans.stopped_by_device_stop:
                steps.run(scans.stop)

        self.watch.stopped(self.config.joint_names if joints is None else joints)
        self.job.pace()  # the confirmation looks often from now until the axes rest
        try:
            self.commands.send(joints, send, urgent=True)  # ahead of every queued read
        finally:
            self.motion_watch.withdraw(joints)
        steps.raise_errors()

    def send_logged(self, joints: Sequence[str] | None) -> None:
        """:meth:`send`, logging instead of raising: the watch sends it again until the
        axes rest (a cancelled move or homing, the dead-man stop)."""
        try:
            self.send(joints)
        except GimbalError as exc:
            self.log.error(f'stop failed: {exc}')

    def confirm(self) -> None:
        """Housekeeping: send the whole stop again to the axes still moving past their
        deceleration time."""
        if not self.connected():
            return
        due = self.watch.due()
        if not due:
            return
        everything = set(due) >= set(self.config.joint_names)
        try:
            self.send(None if everything else due)
        except GimbalError as exc:
            if self.throttle('stop resend', 5.0):
                self.log.error(f'sending the stop again failed: {exc}')

    def stop_all(self) -> str:
        """~/stop after the motion was cancelled: stop every axis, then wait (woken by
        samples) until every axis is at rest, at most its deceleration time plus
        ``stop_margin``. Raises naming the axes still moving and what was sent; with every
        axis at rest it answers, naming a step that failed if one did."""
        joints = self.config.joint_names
        timeout = self.watch.settle_time(*joints)
        failed: GimbalError | None = None
        try:
            self.send(None)
        except GimbalError as exc:
            failed = exc
        moving = self.watch.wait(joints, timeout)
        if moving:
            sent = f' (the device answered: {failed})' if failed else ''
            raise DeviceRefused(f'{self.watch.still_moving(moving)}{sent}; an axis still '
                                'stopping gets the stop again until it rests',
                                reason='stop not confirmed')
        if failed is not None:
            return f'all axes stopped and at rest; but a step of the stop failed: {failed}'
        return 'all axes stopped and at rest; scans, moves and jogs cancelled'

    def confirm_before_close(self, why: str) -> None:
        """Before the link closes (nothing could send the stop again after it): wait for
        the axes to rest, the housekeeping thread resending meanwhile; log what did not."""
        joints = self.config.joint_names
        timeout = self.watch.settle_time(*joints) + SHUTDOWN_CONFIRM_S
        moving = self.watch.wait(joints, timeout) if self.connected() else []
        if moving:
            self.log.error(f'{why}: {self.watch.still_moving(moving)}; closing the '
                           'link anyway')
