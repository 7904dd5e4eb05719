"""The guarded device procedure policy (no ROS): levelling, drift measurement and the like.

A device procedure (:class:`~gimbal_driver_common.device.DeviceProcedure`) is something the
device runs by itself that needs the pedestal to itself. What is the same for every one of
them lives here, once: refuse it while the device runs a program of its own, a scan runs,
a joint moves or another procedure runs; start it; poll it with feedback until it is done;
end it on a cancel, a newer motion command (``motion_generation``), link loss or its
timeout. What is device-specific (how to start it, how far along it is) is the adapter's.
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable

from gimbal_driver_common.device import DeviceProcedure
from gimbal_driver_common.errors import DeviceRefused, GimbalError, LinkError
from gimbal_driver_common.policies import Motion


class GuardedProcedures:
    """Runs one device procedure at a time on top of a controller and its move policy."""

    def __init__(self, motion: Motion) -> None:
        self.motion = motion
        self.controller = motion.controller
        self._running = threading.Lock()
        #: set to end a poll wait early: a cancel request, ~/stop, a joint_command
        self._wake = threading.Event()
        #: ~/stop (a halt) came during the run: it ends as cancelled, not superseded
        self._halted = threading.Event()
        self.controller.halt_hooks.append(self._halt)
        self.controller.preempt_hooks.append(self.wake)

    def _halt(self) -> None:
        self._halted.set()
        self.wake()

    def wake(self) -> None:
        """Look at the running procedure now (a cancel request came, or a command)."""
        self._wake.set()

    def busy_reason(self, procedure: DeviceProcedure) -> str | None:
        """Why the pedestal is not at rest for a procedure, or None."""
        program = procedure.busy()
        if program:
            return program
        if self.motion.scanning:
            return 'a scan is running; stop it with ~/stop_scan first'
        ctl = self.controller
        moving = [j for j in ctl.config.joint_names if ctl.moving(j)]
        if moving:
            return f'{", ".join(moving)} moving; wait for the move to end or call ~/stop'
        return None

    def run(
        self, make: Callable[[], DeviceProcedure], report: Callable[[str], None],
        cancelled: Callable[[], bool] = lambda: False,
    ) -> str:
        """Build, check, start and watch one procedure; return its result message or raise
        GimbalError with the reason it was refused or ended."""
        ctl = self.controller
        procedure = ctl.call(make)
        if not self._running.acquire(blocking=False):  # one at a time: they share the axes
            raise DeviceRefused(f'refused: {procedure.group} is already running')
        try:
            refusal = self.busy_reason(procedure)
            if refusal:
                raise DeviceRefused(refusal)
            self._wake.clear()
            self._halted.clear()
            generation = ctl.motion_generation
            ctl.stop_watch.superseded(procedure.joints)  # the device moves them now
            ctl.call(procedure.start)
            return self._watch(procedure, generation, report, cancelled)
        finally:
            self._running.release()

    def _watch(
        self, procedure: DeviceProcedure, generation: int, report: Callable[[str], None],
        cancelled: Callable[[], bool],
    ) -> str:
        """Poll until done; a cancel or a timeout stops the joints the device moves, a
        newer motion command does not (it owns the axes now, as with a homing)."""
        ctl = self.controller
        joints = list(procedure.joints)
        start = time.monotonic()
        while True:
            if cancelled():
                if joints:
                    ctl.stop_joints(joints)
                raise DeviceRefused(procedure.cancelled)
            if generation != ctl.motion_generation:
                halted = self._halted.is_set()
                raise DeviceRefused(procedure.cancelled if halted
                                    else procedure.superseded or procedure.cancelled)
            if not ctl.connected:
                raise LinkError(f'device link lost during {procedure.name}')
            if procedure.hold_still:
                reason = self.busy_reason(procedure)
                if reason:
                    raise DeviceRefused(f'the pedestal moved during {procedure.name} '
                                        f'({reason}); the result is not trusted')
            elapsed = time.monotonic() - start
            try:
                progress = ctl.call(functools.partial(procedure.poll, elapsed))
            except GimbalError as exc:  # the link dropped after the check above
                if not ctl.connected:
                    raise LinkError(f'device link lost during {procedure.name}') from exc
                raise
            moving = bool(joints) and (ctl.latest is None or any(ctl.moving(j) for j in joints))
            if progress.feedback:
                report(progress.feedback + (' (moving)' if moving else ''))
            if progress.result is not None and not moving:
                return progress.result
            if procedure.timeout is not None and elapsed >= procedure.timeout:
                if joints:
                    ctl.stop_joints(joints)
                raise DeviceRefused(procedure.timed_out)
            self._wake.wait(procedure.period)
            self._wake.clear()
