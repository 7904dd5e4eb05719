"""Move, home, scan and preset policies on top of a :class:`GimbalController` (no ROS).

One :class:`Motion` object per controller gives the node everything its
actions and services need: a move that ends reached, cancelled, stopped, timed
out or with the link lost; homing; a driver-side scan for devices without their
own; and presets where device slots and the YAML store compose.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from gimbal_driver_common.config import scan_joints
from gimbal_driver_common.controller import GimbalController, is_moving
from gimbal_driver_common.device import Moves, TargetPointing
from gimbal_driver_common.errors import DeviceRefused, GimbalError, InvalidRequest, Unsupported
from gimbal_driver_common.joint_command import (
    check_positions,
    resolve_targets,
    validate_targets,
)
from gimbal_driver_common.presets import PresetStore
from gimbal_driver_common.scan import ScanRequest, plan_scan

if TYPE_CHECKING:
    from gimbal_driver_common.geodesy import GeoPoint

#: the patterns a driver-side scan offers
DRIVER_SCAN_PATTERNS = ('sector', 'zigzag', 'square')
#: how often a running move checks its joints
MOVE_CHECK_S = 0.02


class HomingSuperseded(DeviceRefused):
    """A homing ended by a newer motion command (``~/stop``, a move, a preset, a scan)."""

    def __init__(self) -> None:
        super().__init__('homing stopped (~/stop or a new command)')


@dataclass
class MoveOutcome:
    """How a move ended: ``state`` is reached, cancelled, stopped, failed."""

    state: str
    message: str
    positions: list[float] = field(default_factory=list)

    @property
    def success(self) -> bool:
        return self.state == 'reached'


@dataclass
class Preset:
    index: int
    name: str
    positions: dict[str, float]


class MoveTargets(dict[str, float]):
    """A started move's absolute targets (joint -> position), and the motion generation
    its command started: a stop, halt or newer command after it ends the move's wait
    (:meth:`Motion.wait_move`), also one that came before the wait began (a shutdown
    right after the move went out ends it "stopped", not "link lost")."""

    def __init__(self, targets: dict[str, float], generation: int) -> None:
        super().__init__(targets)
        self.generation = generation


class Motion:
    """The policies: every method answers or raises a GimbalError with the reason."""

    def __init__(
        self, controller: GimbalController, store: PresetStore | None = None,
        scan_patterns: Sequence[str] = DRIVER_SCAN_PATTERNS,
    ) -> None:
        self.controller = controller
        self.store = store or PresetStore('')
        #: patterns the driver-side scan offers for this device
        self.scan_patterns = tuple(scan_patterns)
        self._scan_stop = threading.Event()
        self._scan_thread: threading.Thread | None = None
        # a halt ends the driver-side scan; the controller withdraws the watch and moves
        # the generation on itself, after every halt hook ran
        controller.halt_hooks.append(self._scan_stop.set)
        controller.preempt_hooks.append(self._scan_stop_current)

    # ---------------------------------------------------------------- moves
    def start_move(
        self, names: Sequence[str], positions: Sequence[float],
        velocities: Sequence[float] = (), relative: bool = False,
    ) -> MoveTargets:
        """Check and send a MoveTo; returns the absolute targets. Nothing is sent on error."""
        ctl = self.controller
        names = list(names)
        ctl.require(names)
        limits = ctl.config.limits
        targets = resolve_targets(names, list(positions), ctl.positions(), limits,
                                  relative=relative)
        speeds = list(velocities)
        if speeds and len(speeds) != len(names):
            raise InvalidRequest(f'{len(names)} joints but {len(speeds)} velocities')
        moves: Moves = {}
        for i, name in enumerate(names):
            speed = abs(speeds[i]) if speeds and speeds[i] else None
            if speed is not None and speed > limits[name].velocity_max:
                raise InvalidRequest(
                    f'joint {name!r}: speed {speed:.4f} exceeds velocity_max '
                    f'{limits[name].velocity_max:.4f}')
            moves[name] = (targets[name], speed)
        generation = self.preempt()
        offsets = dict(zip(names, map(float, positions), strict=True)) if relative else None
        ctl.send_moves(moves, offsets)
        return MoveTargets(targets, generation)

    def wait_move(
        self, targets: dict[str, float], tolerance: float = 0.0,
        cancelled: Callable[[], bool] = lambda: False,
        feedback: Callable[[list[float]], None] = lambda positions: None,
    ) -> MoveOutcome:
        """Wait until every joint is within tolerance and settled, or the move ends otherwise:
        stopped by a stop, halt or newer command since the move's command (``targets`` as
        :meth:`start_move` or :meth:`point_at` gave them; plain targets: since this call)."""
        ctl = self.controller
        names = list(targets)
        tolerance = tolerance if tolerance > 0 else ctl.config.goal_tolerance
        generation = (targets.generation if isinstance(targets, MoveTargets)
                      else ctl.motion_generation)
        deadline = time.monotonic() + ctl.config.move_timeout
        while True:
            time.sleep(MOVE_CHECK_S)
            current = ctl.positions()
            positions = [current.get(n, math.nan) for n in names]
            feedback(positions)
            if cancelled():
                ctl.stop_joints(names)
                return MoveOutcome('cancelled', 'cancelled', positions)
            if generation != ctl.motion_generation:
                return MoveOutcome('stopped', 'stopped: the driver is shutting down'
                                   if ctl.shutting_down else
                                   'stopped (~/stop or a new command)', positions)
            if not ctl.connected:
                return MoveOutcome('failed', f'device link lost ({ctl.link_error})', positions)
            stalled = ctl.motion_watch.reason(names)
            if stalled:
                ctl.stop_joints(names)
                return MoveOutcome('failed', stalled, positions)
            reached = all(abs(current.get(n, math.inf) - targets[n]) <= tolerance for n in names)
            if reached and not any(is_moving(ctl.latest, n) for n in names):
                return MoveOutcome('reached', 'reached', positions)
            if time.monotonic() > deadline:
                ctl.stop_joints(names)
                return MoveOutcome(
                    'failed', f'not reached within move_timeout {ctl.config.move_timeout:g} s',
                    positions)

    def point_at(self, pointing: TargetPointing, target: GeoPoint,
                 targets: dict[str, float]) -> tuple[str, MoveTargets]:
        """Start the device's own pointing at ``target``; ``targets`` is where the
        driver's own solution puts the joints (already checked against the limits), which
        ~/status shows. Returns the device's answer and the targets to wait for with
        :meth:`wait_move`."""
        ctl = self.controller
        ctl.require(list(targets))
        generation = self.preempt()
        ctl.watchdog.cancel(list(targets))
        message = ctl.call(lambda: pointing.point_at(target))
        ctl.record_targets(targets)
        return message, MoveTargets(targets, generation)

    def _scan_stop_current(self) -> None:
        self._scan_stop.set()

    def preempt(self) -> int:
        """A new motion command ends a driver-side scan and supersedes a running move goal
        (which then ends "stopped"), so waiting goals never pile up; a device scan ends
        with the device's new move. The joint_commands still queued behind a busy link
        (and the moves of a posted write not yet settled) are dropped, every joint's: none
        from before this command may reach the device after it. Returns the generation the
        new command runs in."""
        self._scan_stop.set()
        self.controller.commands.drop(None)
        self.controller.motion_watch.withdraw()
        self.controller.stop_watch.superseded()  # the new command owns the axes
        return self.controller.bump_motion_generation()

    # ---------------------------------------------------------------- homing
    def home(
        self, joints: Sequence[str], report: Callable[[str], None],
        cancel_requested: Callable[[], bool] = lambda: False,
    ) -> str:
        """Home ``joints``; the device's wait ends (its ``cancelled`` Event is set) when
        ``cancel_requested()`` turns true or a newer motion command supersedes the homing.

        Raises :class:`HomingSuperseded` in the second case, so the caller ends the goal
        without stopping the axes the newer command moves; after a cancel request it raises
        DeviceRefused('homing cancelled') and the caller stops the axes.
        """
        ctl = self.controller
        joints = list(joints) or list(ctl.config.joint_names)
        unknown = [j for j in joints if j not in ctl.config.limits]
        if unknown:
            raise InvalidRequest(
                f'unknown joint(s) {unknown}; this device has {ctl.config.joint_names}')
        homing = ctl.device.capabilities.homing
        if homing is None:
            ctl.require()
            raise Unsupported('this device has no homing routine')
        self.preempt()
        ctl.watchdog.cancel(joints)
        generation = ctl.motion_generation
        cancelled, done = threading.Event(), threading.Event()

        def superseded() -> bool:
            return ctl.motion_generation != generation

        def watch() -> None:
            # a device's wait sees only the Event: cancel and supersession both set it
            while not done.wait(MOVE_CHECK_S):
                if cancel_requested() or superseded():
                    cancelled.set()
                    return

        threading.Thread(target=watch, name='home-watch', daemon=True).start()
        try:
            answer = ctl.call(lambda: homing.home(joints, report, cancelled)) or 'homed'
        except GimbalError as exc:  # e.g. "homing cancelled" from a wait the Event ended
            if superseded():
                raise HomingSuperseded() from exc
            raise
        finally:
            done.set()
        if superseded():
            raise HomingSuperseded()
        if cancel_requested():
            raise DeviceRefused('homing cancelled')
        return answer

    # ----------------------------------------------------------------- scans
    def scan_joints(self) -> list[str]:
        return scan_joints(self.controller.config)

    def start_scan(self, request: ScanRequest) -> str:
        ctl = self.controller
        ctl.require(self.scan_joints())
        scans = ctl.device.capabilities.scans
        if scans is not None and request.pattern in scans.patterns:
            self.preempt()
            return ctl.call(lambda: scans.start(request))
        waypoints = plan_scan(request, self.scan_joints(), ctl.positions(), ctl.config.limits,
                              self.scan_patterns)
        self.preempt()
        self._scan_stop = stop = threading.Event()
        self._scan_thread = threading.Thread(
            target=self._run_scan, args=(waypoints, request, stop), name='scan', daemon=True)
        self._scan_thread.start()
        return f'{request.pattern} scan started over {len(waypoints)} waypoints (driver-side)'

    def stop_scan(self) -> str:
        self.preempt()
        self.controller.require()
        self.controller.stop()
        return 'scan stopped'

    @property
    def scanning(self) -> bool:
        return self._scan_thread is not None and self._scan_thread.is_alive()

    def _run_scan(
        self, waypoints: list[dict[str, float]], scan: ScanRequest, stop: threading.Event
    ) -> None:
        ctl = self.controller
        pan = self.scan_joints()[0]
        index = 0
        while not stop.is_set() and ctl.connected:
            target = waypoints[index % len(waypoints)]
            try:
                ctl.send_moves({n: (p, scan.speed if n == pan else None)
                                for n, p in target.items()})
            except Exception as exc:  # noqa: BLE001 - the scan thread reports and ends
                ctl.log.error(f'scan aborted: {exc}')
                return
            deadline = time.monotonic() + ctl.config.move_timeout
            while not stop.is_set() and time.monotonic() < deadline:
                current = ctl.positions()
                if all(abs(current.get(n, math.inf) - p) <= ctl.config.goal_tolerance * 2
                       for n, p in target.items()):
                    break
                stop.wait(MOVE_CHECK_S)
            stop.wait(scan.dwell)
            index += 1

    # --------------------------------------------------------------- presets
    def _device_slot(self, index: int):
        presets = self.controller.device.capabilities.presets
        return presets if presets is not None and presets.handles(index) else None

    def set_preset(
        self, index: int, name: str, positions: dict[str, float] | None
    ) -> str:
        """Store a preset; ``positions`` None: the current position."""
        ctl = self.controller
        if positions is not None:
            check_positions(positions, ctl.config.limits)
        device = self._device_slot(index)
        if device is not None:
            return ctl.call(lambda: device.set(index, name, positions))
        if positions is None:
            current = ctl.positions()
            if not current:
                raise DeviceRefused('no joint position received yet')
            positions = {n: current[n] for n in ctl.config.joint_names if n in current}
        self.store.set(index, name, positions)
        return f'preset {index} stored: ' + ', '.join(
            f'{k}={v:.4f}' for k, v in positions.items())

    def goto_preset(self, index: int, speed: float) -> str:
        ctl = self.controller
        if speed < 0 or not math.isfinite(speed):
            raise InvalidRequest(f'speed {speed} must be >= 0 rad/s')
        device = self._device_slot(index)
        if device is not None:
            ctl.require(ctl.config.joint_names)
            self.preempt()
            message = ctl.call(lambda: device.goto(index, speed))
            ctl.record_targets(device.target(index) or {})
            return message
        preset = self.store.get(index)
        names = [n for n in preset.positions if n in ctl.config.limits]
        ctl.require(names)
        speeds = [speed] * len(names) if speed > 0 else []
        moves = validate_targets(names, [preset.positions[n] for n in names],
                                 ctl.config.limits, speeds)
        self.preempt()
        ctl.send_moves(moves)
        return f'moving to preset {index} ({preset.name})'

    def list_presets(self) -> list[Preset]:
        """Device slots (when the device is connected) and YAML slots, by index."""
        found = {p.index: Preset(p.index, p.name, dict(p.positions)) for p in self.store.list()}
        presets = self.controller.device.capabilities.presets
        if presets is not None:
            for index, name, positions in self.controller.call(presets.list):
                found[index] = Preset(index, name, positions)
        return [found[i] for i in sorted(found)]

    def clear_preset(self, index: int | None) -> str:
        presets = self.controller.device.capabilities.presets
        if index is None:
            if presets is not None:
                self.controller.call(lambda: presets.clear(None))
            self.store.clear(None)
            return 'all presets cleared'
        device = self._device_slot(index)
        if device is not None:
            return self.controller.call(lambda: device.clear(index))
        self.store.clear(index)
        return f'preset {index} cleared'
