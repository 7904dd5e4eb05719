"""Capture simulator: injectable faults, device constants and one motor axis."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from gimbal_driver_common.sim_motion import AxisMotion

from ..protocol import COMMANDS, ReplyCode
from ..protocol import registers as reg

#: Bits the simulator can latch as an injected axis fault (MER bit numbers).
FAULTS = {
    'can_bus_error': 0, 'short_circuit': 1, 'control_error': 3, 'communication_error': 4,
    'over_current': 8, 'i2t_error': 9, 'motor_over_temperature': 10, 'over_voltage': 12,
    'under_voltage': 13,
}
# MER bit -> CMER bit for the faults above (4.10.6 groups them).
_MER_TO_CMER = {0: 15, 1: 11, 3: 10, 8: 7, 9: 6, 12: 5, 13: 4}
SYSTEM_FAULTS = {flag.name: flag.bit for flag in reg.CSR.flags}

HOMING_SPEED = 30.0  # deg/s, sim: the stored homing profile
GENERAL_SPEED = 30.0  # deg/s, default CFG_SetGeneralSpd
TILT_HARD_LIMIT = 95.0  # deg, sim: mechanical limit switches of the tilt axis
GYRO_BIAS = 0.05  # deg/s, sim: the yaw gyro drift IMU_GyroDriftCompensation measures
DRIFT_MEASURE_TIME = 2.0  # s (simulated), sim: how long the drift calculation takes

#: the motion set-up of 7.1 (TUM aside) and the speed mode of jogs and stops
MOTION_SETUP = ('MOT_SetPositionMode', 'MOT_SetSpeedMode', 'MOT_SetPositionAbsolute',
                'MOT_SetPositionRelative', 'MOT_SetAcceleration', 'MOT_SetSpeed',
                'MOT_SendPosition', 'MOT_Update')
#: named command subsets for ``known_commands`` (``--only``): controllers that know only
#: part of the table (a third-party simulator, firmware without some subsystems)
KNOWN_SETS: dict[str, tuple[str, ...]] = {
    # a third-party Cap-Track simulator: motion, load position and speed, voltage, current,
    # the motor error register and COM_Connect (it ACKs the rest: ``--ack-unknown``)
    'third-party': ('COM_Connect', *MOTION_SETUP, 'MOT_SetTum', 'MOT_GetLoadPosition',
                    'MOT_GetMotorSpeed', 'MOT_GetMotorVoltage', 'MOT_GetMotorCurrent',
                    'MOT_MerRegister'),
    # a partial controller: COM_Connect, the joint poll and the motion set-up without TUM
    'partial': ('COM_Connect', 'MOT_GetLoadPosition', 'MOT_GetMotorSpeed', *MOTION_SETUP),
}


def command_names(names: Iterable[str]) -> list[str]:
    """Table command names, with the names of :data:`KNOWN_SETS` expanded; a name that is
    neither raises KeyError naming it."""
    expanded: list[str] = []
    for name in names:
        if name in KNOWN_SETS:
            expanded += KNOWN_SETS[name]
        elif name in COMMANDS:
            expanded.append(name)
        else:
            raise KeyError(f'{name!r} is neither a table command nor one of {sorted(KNOWN_SETS)}')
    return expanded


@dataclass
class AxisModel(AxisMotion):
    """One motor axis in load degrees, on the shared trapezoidal model (``AxisMotion``:
    ``target`` is the position move, ``jog_velocity`` the speed-mode velocity, ``speed``
    the profile speed, ``acceleration`` the profile acceleration and deceleration)."""

    number: int = 0
    acceleration: float = 180.0
    speed: float | None = 0.0  # sim: COM_Connect sets speed 0 (4.6.2)
    jog_velocity: float | None = 0.0
    speed_mode: bool = False
    relative: bool = True
    pending_position: float | None = None
    axis_on: bool = True
    homing: bool = False
    homed: bool = True
    mer_latched: int = 0
    der_latched: int = 0
    swls_neg: float = -180.0
    swls_pos: float = 180.0
    swls_active: bool = False
    hard_limits: tuple[float, float] | None = None
    general_speed: float = GENERAL_SPEED
    current_ma: float = 0.0
    limit_flags: int = 0  # DER bits 6/7 (software) and MER bits 6/7 (hardware) while at limit
    stored: dict[str, object] = field(default_factory=dict)

    @property
    def faulted(self) -> bool:
        return bool(self.mer_latched or self.der_latched & 0b0010_0100_0000_0011)

    @property
    def moving(self) -> bool:
        return abs(self.velocity) > 1e-6 or self.target is not None or self.homing

    def stop(self, immediate: bool = False) -> None:
        """End the move, jog or homing run (braking at the profile's rate unless immediate)."""
        super().stop(immediate)
        self.jog_velocity = 0.0
        self.homing = False

    def halt(self) -> None:
        """Immediate stop (emergency stop, fault, keep-alive expiry)."""
        self.stop(immediate=True)

    def goal(self) -> tuple[float | None, float | None]:
        if self.homing:
            return 0.0, HOMING_SPEED
        return self.target, self.speed

    def on_arrival(self) -> None:
        if self.homing:
            self.homing, self.homed = False, True
        self.target = None

    def _active_limits(self) -> tuple[float | None, float | None]:
        """The switches that stop the axis: software limits when active, hardware always."""
        lows, highs = [], []
        if self.swls_active:
            lows.append(self.swls_neg)
            highs.append(self.swls_pos)
        if self.hard_limits is not None:
            lows.append(self.hard_limits[0])
            highs.append(self.hard_limits[1])
        return (max(lows) if lows else None), (min(highs) if highs else None)

    def step(self, dt: float) -> bool:
        if self.faulted or not self.axis_on:
            self.velocity = 0.0
            return False
        previous = self.velocity
        self.set_limits(*self._active_limits())
        came_to_rest = super().step(dt)
        change = self.velocity - previous
        self.current_ma = 200.0 + 5.0 * abs(self.velocity) + 0.5 * abs(change) / max(dt, 1e-6)
        self._enforce_limits()
        return came_to_rest

    def _enforce_limits(self) -> None:
        """Limit-switch flags while the axis rests on a switch (the motion model has already
        stopped it there); a move or jog still pushing outward is dropped."""
        self.limit_flags = 0
        checks = []
        if self.swls_active:
            checks.append((self.swls_neg, self.swls_pos, 'software'))
        if self.hard_limits is not None:
            checks.append((*self.hard_limits, 'hardware'))
        for low, high, kind in checks:
            bit = None
            if self.position <= low + 1e-6:
                bit = 7
                if self.position < low or self.velocity < 0 or (
                        self.target is not None and self.target < low):
                    self.position = low
                    self.halt()
            elif self.position >= high - 1e-6:
                bit = 6
                if self.position > high or self.velocity > 0 or (
                        self.target is not None and self.target > high):
                    self.position = high
                    self.halt()
            if bit is not None:  # the switch stays active while the axis rests on it
                self.limit_flags |= (1 << bit) << (0 if kind == 'hardware' else 16)

    # ---------------------------------------------------------------- registers
    def mer(self) -> int:
        value = self.mer_latched | (self.limit_flags & 0xC0)
        return value

    def der(self) -> int:
        value = self.der_latched | ((self.limit_flags >> 16) & 0xC0)
        return value

    def srh(self) -> int:
        value = 1  # drive initialised
        if self.target is None and not self.homing and abs(self.velocity) < 1e-6:
            value |= reg.SRH_TARGET_REACHED
        if self.limit_flags & 0x40 or (self.limit_flags >> 16) & 0x40:
            value |= 1 << 6
        if self.limit_flags & 0x80 or (self.limit_flags >> 16) & 0x80:
            value |= 1 << 7
        if self.faulted:
            value |= reg.SRH_FAULT
        return value

    def srl(self) -> int:
        value = 0
        if self.homing:
            value |= reg.SRL_HOMING_ACTIVE
        if not self.moving:
            value |= reg.SRL_MOTION_COMPLETE
        if self.axis_on:
            value |= reg.SRL_AXIS_ON
        return value

    def msr(self) -> int:
        value = 1
        if self.mer_latched & (1 << 3):
            value |= 1 << 3
        if self.limit_flags & 0x40 or (self.limit_flags >> 16) & 0x40:
            value |= 1 << 6
        if self.limit_flags & 0x80 or (self.limit_flags >> 16) & 0x80:
            value |= 1 << 7
        if not self.moving:
            value |= 1 << 9
        if self.axis_on:
            value |= 1 << 13
        return value

    def cmer(self) -> int:
        value = 0
        if self.faulted:
            value |= 1
        if self.axis_on:
            value |= 1 << 1
        if not self.moving:
            value |= 1 << 2
        for mer_bit, cmer_bit in _MER_TO_CMER.items():
            if self.mer_latched & (1 << mer_bit):
                value |= 1 << cmer_bit
        if self.limit_flags & 0x80:
            value |= 1 << 8
        if self.limit_flags & 0x40:
            value |= 1 << 9
        if (self.limit_flags >> 16) & 0x80:
            value |= 1 << 13
        if (self.limit_flags >> 16) & 0x40:
            value |= 1 << 14
        return value

    def operation(self) -> int:
        return 0 if self.homed else reg.OPR_HOMING_NOT_COMPLETED


class RequestRejected(Exception):
    """Answer the request with this NACK code; ``reason`` becomes the protocol error string."""

    def __init__(self, code: ReplyCode, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


@dataclass
class ScanState:
    waypoints: list[tuple[float, float]]
    index: int = 0
    direction: int = 1
