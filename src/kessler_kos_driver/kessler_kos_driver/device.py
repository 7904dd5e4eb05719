"""The kOS device adapter: KosClient on the shared device contract, in SI units (no ROS).

The device works in motor rotations; everything the controller and the node see is SI
(rad, or m for a slider). Each joint converts by the rule of :mod:`kessler_kos_driver.units`:
a calibrated axis with a span reports ``offset + rotations * span / end_position``, any
other ``offset + rotations * joint_scale``. The end position is the one the device reports
(read at every connect, after every MarkEnd and by every MotorInfo poll), so the conversion
follows a recalibration. Every scale, sign and unit conversion of the driver lives here:
:meth:`KosDevice.read` (rotations -> SI), :meth:`KosDevice.move` and :meth:`KosDevice.jog`
(SI -> rotations, checked against the calibrated range and the motor maxima, in SI, before
anything is sent), the key-frame load, homing to the begin mark, the calibration range,
~/playback_status positions and the diagnostics values (with the ``units`` key).

Capabilities: :class:`~.homing.KosHoming` (first key frame of a loaded move, else the begin
marks) and :class:`~.status.KosStatus` (ErrorStatus latch, lock state, per-motor
diagnostics). kOS has no device
presets and no device scans, so the controller's YAML presets and driver-side scans serve it.
The playback, calibration, picture, LED and SoftwareID requests the node exposes as its own
services are the adapter's parts, called through ``controller.call``: the playback ones
:attr:`KosDevice.playback` (:class:`~.playback.KosPlayback`), the others
:attr:`KosDevice.functions` (:class:`~.device_functions.KosFunctions`); each is handed the
client, the joint table and the adapter's public conversion and checks.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

from gimbal_driver_common.device import Device, DeviceInfo, JointSample, Moves, PostedWrite
from gimbal_driver_common.errors import DeviceRefused, EverySteps, InvalidRequest
from gimbal_driver_common.joint_command import JointLimits

from .client import KosClient, MotorState, NotConnected
from .device_functions import KosFunctions
from .homing import KosHoming
from .moves import JointMapping
from .playback import KosPlayback, PlaybackReport
from .protocol import DeviceType, playback_state_name
from .status import KosStatus
from .units import Conversion, JointUnits

LOG = logging.getLogger('kessler_kos_driver.device')

DEVICE_MODELS: dict[int, str] = {
    DeviceType.CINESHOOTER: 'Kessler CineShooter',
    DeviceType.SECOND_SHOOTER_PRO: 'Kessler Second Shooter Pro',
    DeviceType.SECOND_SHOOTER_PLUS: 'Kessler Second Shooter Plus',
}


class MotionConfig(Protocol):
    """What the adapter reads from the controller's configuration (live, runtime parameters)."""

    limits: dict[str, JointLimits]
    move_timeout: float
    goal_tolerance: float


@dataclass
class KosSettings:
    """kOS-specific tuning the node changes at run time (``ros2 param set``)."""

    acceleration_scale: float = 0.5    # fraction of MaxMaxAcceleration for moves and jogs
    playback_timeout: float = 60.0     # s to wait for SetupCompleted / MotorsHome


class KosDevice(Device):
    """One kOS device (TCP or USB HID) in SI units; callbacks run on the client's reader."""

    #: positions come from MotorInfo polls (every ``poll_period``) and notifications
    streamed = True

    def post(self, moves: Moves, jogs: dict[str, float]) -> PostedWrite:
        """A move is one kOS message written to the link; no reply is awaited.
        Written from the caller's thread, with no answer to settle."""
        return self.write_now(moves, jogs)

    def __init__(
        self, client: KosClient, joints: Sequence[JointMapping], config: MotionConfig,
        settings: KosSettings | None = None,
        on_playback: Callable[[PlaybackReport], None] | None = None,
        on_aux_inputs: Callable[[int], None] | None = None,
    ) -> None:
        super().__init__()
        self.client = client
        self.joints = {m.name: m for m in joints}
        self._given_config = config
        self.settings = settings or KosSettings()
        self.on_aux_inputs = on_aux_inputs or (lambda status: None)
        self.playback = KosPlayback(client, self.joints, self.settings,
                                    on_playback or (lambda report: None), adapter=self)
        self.functions = KosFunctions(client, self.joints, adapter=self)
        self.status = KosStatus(self)
        self.capabilities.homing = KosHoming(self)
        self.capabilities.status = self.status
        client.notifications.on_motor_update = self.notify_data
        client.notifications.on_playback = self.playback.notified
        client.notifications.on_aux_inputs = lambda status: self.on_aux_inputs(status)
        client.notifications.on_error = self.status.latch
        #: end mark (rotations) per joint as last seen, to log a recalibration
        self._ends: dict[str, float] = {}
        self._ends_lock = threading.Lock()   # the device thread and services both look

    @property
    def motion_config(self) -> MotionConfig:
        """The controller's live configuration once it attached one, else the one given."""
        return self.config if self.config is not None else self._given_config

    # ------------------------------------------------------------ conversion
    def joint_of(self, address: int) -> str | None:
        return next((m.name for m in self.joints.values() if m.address == address), None)

    def conversion(self, joint: str) -> Conversion:
        """The joint's SI conversion at the calibration the device last reported."""
        mapping = self.joints[joint]
        motor = self.client.motors.get(mapping.address)
        return mapping.units.conversion(motor.end_position if motor is not None else 0.0)

    def to_si(self, joint: str, rotations: float) -> float:
        """A position in rotations as SI."""
        return self.conversion(joint).to_si(rotations)

    def set_units(self, units: Sequence[JointUnits], targets: dict[str, float]) -> None:
        """New unit parameters per joint (order of the joints); ``targets`` (SI, by joint,
        e.g. the controller's commanded targets) keep their motor positions: reported in
        the new units (:meth:`report_targets`)."""
        before = {name: self.conversion(name) for name in self.joints}
        for (name, mapping), joint_units in zip(list(self.joints.items()), units, strict=True):
            self.joints[name] = JointMapping(name, mapping.address, joint_units)
        self.report_targets({
            name: self.conversion(name).to_si(before[name].to_rotations(target))
            for name, target in targets.items() if name in before})

    def units_report(self) -> dict[str, str]:
        """Joint -> what its joint_states mean now (the diagnostics ``units`` value)."""
        return {name: self.conversion(name).describe() for name in self.joints}

    def set_poll_period(self, period: float) -> None:
        """s between MotorInfo polls (the client reads it on every poll tick)."""
        self.client.poll_period = period

    def note_calibration(self) -> None:
        """Log each change of a joint's end mark, and what the joint's units become."""
        for name, mapping in self.joints.items():
            motor = self.client.motors.get(mapping.address)
            if motor is None:
                continue
            end = motor.end_position
            with self._ends_lock:
                before = self._ends.get(name)
                self._ends[name] = end
            if before is not None and before != end:
                LOG.info('joint %r: end mark now %.6g rotations (was %.6g); positions are %s',
                         name, end, before, self.conversion(name).describe())

    # ------------------------------------------------------------- contract
    def open(self) -> DeviceInfo:
        client = self.client
        client.connect()
        missing = [f'{m.name} (motor {m.address})' for m in self.joints.values()
                   if m.address not in client.motors]
        if missing:
            LOG.warning('joints without a connected motor: %s; device motors: %s', missing,
                        sorted(client.motors))
        self.status.locked_out = False
        self.note_calibration()   # an end mark changed while the link was down is logged
        self.functions.read_device_settings()
        self.on_aux_inputs(client.aux_inputs)
        info = client.device_info
        model = (DEVICE_MODELS.get(info.device_type, f'kOS device type {info.device_type}')
                 if info else 'kOS device')
        return DeviceInfo(model=model, serial_number=client.guid,
                          firmware_version=info.firmware if info else '',
                          hardware_id=client.guid or client.description)

    def close(self) -> None:
        self.client.close()

    def description(self) -> str:
        return self.client.description

    def link_healthy(self) -> bool:
        """The client sees a lost link first (read/write error, silent device): its reason."""
        if not self.client.connected:
            raise NotConnected(self.client.last_error_text or 'link down')
        return True

    def read(self) -> JointSample | None:
        """Motor positions (rotations) as SI; offline or never-reported motors are left out.

        kOS has no per-motor "moving" bit, but a playing move owns every motor: then every
        joint reads moving; otherwise the controller's velocity rule applies.

        The stamp is the oldest report in the sample: the motors' positions arrive at
        different times (the MotorInfo poll for all, MotorPosition notifications for one),
        and one JointState stamp must not claim a position fresher than it is. With the
        newest report as the stamp, a held joint's notification every cycle made a moving
        joint's 20 ms old position look current (the tracking bench read it as 10 mrad of
        extra error).
        """
        client = self.client
        positions: dict[str, float] = {}
        velocities: dict[str, float] = {}
        stamp = math.inf
        self.note_calibration()
        for name, mapping in self.joints.items():
            motor = client.motors.get(mapping.address)
            if motor is None or not motor.online or not motor.stamp:
                continue
            units = self.conversion(name)
            positions[name] = units.to_si(motor.position)
            velocities[name] = units.rate_to_si(motor.velocity)
            stamp = min(stamp, motor.stamp)
        if not positions:
            return None
        moving = dict.fromkeys(positions, True) if client.playback_running else {}
        return JointSample(positions, velocities, stamp=stamp, moving=moving)

    def playing(self) -> str | None:
        """Why nothing else may move or load now: a playing move owns the motors."""
        client = self.client
        if client.playback_running:
            return (f'a move is playing ({playback_state_name(client.playback.status)}); '
                    'call ~/stop_playback or ~/stop first')
        return None

    def refusal(self, joints: Sequence[str]) -> str | None:
        """A playing move owns the motors; an offline or missing motor cannot move."""
        reason = self.playing()
        if reason:
            return reason
        client = self.client
        for name in joints:
            if name not in self.joints:
                continue   # an unknown joint is the command check's to name
            address = self.joints[name].address
            motor = client.motors.get(address)
            if motor is None:
                return f'joint {name!r}: motor {address} is not connected'
            if not motor.online:
                return f'joint {name!r}: motor {address} is offline'
        return None

    def require_idle(self) -> None:
        """Refuse while a move plays (loads, setups, calibration, moves)."""
        reason = self.playing()
        if reason:
            raise DeviceRefused(reason)

    def _motor(self, joint: str) -> MotorState:
        address = self.joints[joint].address
        if address not in self.client.motors:
            raise DeviceRefused(f'joint {joint!r}: motor {address} is not connected')
        return self.client.motor(address)

    def _acceleration(self, motor: MotorState) -> float:
        return motor.max_acceleration * self.settings.acceleration_scale

    def move(self, moves: Moves) -> None:
        """Absolute moves: every target and speed is checked, here and once, before anything
        is sent (the client sends rotations unchecked).

        No speed: the joint's velocity_max, capped at the motor's MaxMaxSetupSpeed.
        """
        self.require_idle()
        client = self.client
        checked = []
        for name, (target, speed) in moves.items():
            motor = self._motor(name)
            units = self.conversion(name)
            wanted = speed if speed is not None else self.motion_config.limits[name].velocity_max
            speed_rot = abs(units.rate_to_rotations(wanted))
            if speed is None:
                speed_rot = min(speed_rot, motor.max_setup_speed)
            else:
                self._check_speed(name, units, motor, abs(wanted))
            rotations = self._check_travel(name, units, motor, target)
            checked.append((motor.address, rotations, speed_rot, self._acceleration(motor)))
        for address, rotations, speed_rot, acceleration in checked:
            client.commands.move_to(address, rotations, speed_rot, acceleration)

    @staticmethod
    def _check_travel(name: str, units: Conversion, motor: MotorState, target: float) -> float:
        """The calibrated range (or the uncalibrated travel) in SI, before any byte is sent;
        the target in rotations (kept inside the range)."""
        low, high = motor.travel()
        rotations = units.to_rotations(target) if math.isfinite(target) else math.nan
        if not low - 1e-9 <= rotations <= high + 1e-9:
            si_low, si_high = sorted((units.to_si(low), units.to_si(high)))
            state = 'calibrated range' if motor.calibrated else 'uncalibrated travel'
            raise InvalidRequest(
                f'joint {name!r}: {target:.4f} is outside the {state} [{si_low:.4f}, '
                f'{si_high:.4f}] ({units.describe()}; motor {motor.address}: {low:g} .. '
                f'{high:g} rotations)')
        return min(max(rotations, low), high)

    @staticmethod
    def _check_speed(name: str, units: Conversion, motor: MotorState, speed: float) -> None:
        """A speed (SI, no direction) against the motor's MaxMaxSetupSpeed, in SI."""
        if not math.isfinite(speed):
            raise InvalidRequest(f'joint {name!r}: speed must be a finite number, got {speed}')
        if abs(units.rate_to_rotations(speed)) > motor.max_setup_speed:
            raise InvalidRequest(
                f'joint {name!r}: speed {speed:.4f} exceeds the motor maximum '
                f'{units.magnitude_to_si(motor.max_setup_speed):.4f} (MaxMaxSetupSpeed '
                f'{motor.max_setup_speed:g} rot/s, {units.describe()})')

    def jog(self, velocities: dict[str, float]) -> None:
        """Velocities (SI/s) as moves toward the end of travel at that speed (0 stops)."""
        self.require_idle()
        motors = {name: self._motor(name) for name in velocities}
        rotations = {}
        for name, velocity in velocities.items():
            units = self.conversion(name)
            self._check_speed(name, units, motors[name], abs(velocity))
            rotations[name] = units.rate_to_rotations(velocity)
        for name, velocity in rotations.items():
            motor = motors[name]
            self.client.commands.jog(motor.address, velocity, self._acceleration(motor))

    def stop(self, joints: Sequence[str] | None = None) -> None:
        client = self.client
        if joints is None:
            client.commands.stop_all()
            return
        with EverySteps() as steps:  # one motor's failed write skips no other
            for name in joints:
                motor = client.motors.get(self.joints[name].address)
                if motor is not None and motor.online:
                    steps.run(client.commands.stop_motor, motor.address)

    def reset_faults(self) -> str:
        """kOS has no fault-clear command: clear the latched errors and re-read MotorInfo."""
        count = self.status.clear()
        client = self.client
        client.refresh_motors()
        uncalibrated = [n for n, m in self.joints.items()
                        if m.address in client.motors and not client.motors[m.address].calibrated]
        note = (f'; not calibrated (recalibrate with ~/calibrate): {uncalibrated}'
                if uncalibrated else '')
        return f'cleared {count} latched device error(s){note}'


def joint_mappings(
    names: Sequence[str], addresses: Sequence[int], units: Sequence[JointUnits]
) -> list[JointMapping]:
    """The joint -> (motor address, units) table from the parameters."""
    return [JointMapping(n, a, u) for n, a, u in zip(names, addresses, units, strict=True)]

