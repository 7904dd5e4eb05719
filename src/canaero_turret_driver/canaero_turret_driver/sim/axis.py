"""Turret simulator: device constants, EED codes, one drive, node memories, the configuration."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

from gimbal_driver_common.sim_motion import AxisMotion

from ..protocol import nodeservice as ns
from ..protocol.identifiers import (
    DEFAULT_ZOOM_POSITION_ID,
    TURRET_NODE_ID,
    ActuatorMode,
    TargetState,
)

DEFAULT_FPS_SECURITY_CODE = 0x5A
YAW, PITCH = "yaw", "pitch"


class EedCode(IntEnum):
    """Error codes the simulator puts in EED messages."""

    COMMAND_REJECTED = 0x0001  # axis in free run or faulted
    WRONG_DATA_TYPE = 0x0002
    SETPOINT_OUT_OF_RANGE = 0x0003
    DRIVE_FAULT = 0x0010  # injected drive fault
    INJECTED = 0x00FF  # raw injected event


class Operation(IntEnum):
    NONE = 0
    POSITION = 1
    VELOCITY = 2
    RELATIVE = 3
    MODE = 4
    STOP = 5
    OTHER = 6


LOCATION = {YAW: 1, PITCH: 2}

#: set-point command (key after the axis name) -> (operation named in a refusal's EED, the
#: AxisModel motion it starts, whether the value must lie in the axis range)
SETPOINTS: dict[str, tuple[Operation, str, bool]] = {
    "position_setpoint": (Operation.POSITION, "move_to", True),
    "velocity_setpoint": (Operation.VELOCITY, "jog", False),
    "relative_setpoint": (Operation.RELATIVE, "move_by", False),
}
#: on/off controls (value 0 or 1) -> the simulator attribute they switch
SWITCHES = {"fan_control": "fan_on", "oes_heater_control": "oes_heater_on",
            "drives_heater_control": "drives_heater_on", "charging_control": "charging_on"}

# Default transmission intervals in ms (the ICD only fixes cover state = 100 ms). A real
# turret sends its positions and velocities every 100 ms until a master asks for more by
# TIS, so the simulator does the same; the slower ones are simulator choices.
DEFAULT_INTERVALS_MS: dict[str, int] = {
    "yaw_position": 100, "yaw_velocity": 100, "pitch_position": 100, "pitch_velocity": 100,
    "yaw_status": 100, "pitch_status": 100, "yaw_actuator_mode_state": 500,
    "pitch_actuator_mode_state": 500, "yaw_current": 200, "pitch_current": 200,
    "yaw_motor_temperature": 1000, "pitch_motor_temperature": 1000,
    "yaw_power_stage_temperature": 1000, "pitch_power_stage_temperature": 1000,
    "yaw_bus_voltage": 1000, "pitch_bus_voltage": 1000, "yaw_humidity": 1000,
    "pitch_humidity": 1000, "yaw_revolutions": 500, "pitch_revolutions": 500,
    "fan_state": 500, "case_temperature": 1000, "charging_current": 1000,
    "charging_state": 500, "oes_heater_state": 500, "drives_heater_state": 1000,
    "periphery_status": 200, "global_pitch": 200, "global_roll": 200,
    "cover_state": 100, "rover_heading": 200, "rover_heading_accuracy": 1000,
    "global_yaw": 200, "latitude": 500, "longitude": 500, "altitude_msl": 500,
    "position_accuracy": 1000, "utc_time": 1000, "zoom_position": 200,
}
MIN_INTERVAL_MS = 10
MAX_INTERVAL_MS = 10000


class AxisModel(AxisMotion):
    """One drive on the shared trapezoidal model (``AxisMotion``), in degrees.

    Positions are kept unwrapped; a continuous axis (yaw, no limits) reports them
    wrapped to -180..180 and counts revolutions, a limited axis (pitch) stops at its
    limits. ``mode`` is the drive's idle | position | velocity.
    """

    def __init__(self, name: str, max_velocity: float, acceleration: float,
                 min_position: float | None = None,
                 max_position: float | None = None) -> None:
        super().__init__(max_speed=max_velocity, acceleration=acceleration,
                         min_position=min_position, max_position=max_position)
        self.name = name
        self.actuator_mode: int = ActuatorMode.AUTO_BRAKE
        self.fault = False

    @property
    def max_velocity(self) -> float:
        return self.max_speed

    @property
    def mode(self) -> str:
        if self.target is not None:
            return "position"
        return "velocity" if self.jog_velocity is not None else "idle"

    @property
    def continuous(self) -> bool:
        return self.min_position is None

    @property
    def enabled(self) -> bool:
        return not self.fault and self.actuator_mode != ActuatorMode.FREE_RUN

    @property
    def reported_position(self) -> float:
        if self.continuous:
            return (self.position + 180.0) % 360.0 - 180.0
        return self.position

    @property
    def revolutions(self) -> int:
        return math.floor((self.position + 180.0) / 360.0) if self.continuous else 0

    @property
    def target_state(self) -> int:
        if self.mode == "velocity":
            return TargetState.JOG
        if self.mode == "position":
            return TargetState.NOT_REACHED
        return TargetState.REACHED if abs(self.velocity) < 1e-6 else TargetState.NOT_REACHED

    def in_range(self, position: float) -> bool:
        if self.continuous:
            return -180.0 <= position <= 180.0
        assert self.min_position is not None and self.max_position is not None
        return self.min_position <= position <= self.max_position

    def move_to(self, position: float, speed: float | None = None) -> None:
        """Absolute set-point; a continuous axis takes the short way round."""
        if self.continuous:
            position = self.position + (position - self.reported_position + 180.0) % 360.0 - 180.0
        super().move_to(position, speed)

    def move_by(self, delta: float) -> None:
        base = self.target if self.target is not None else self.position
        super().move_to(base + delta)  # a limited axis clamps to its limits

    def step(self, dt: float) -> bool:
        if dt <= 0:
            return False
        if not self.enabled:
            self.stop()  # a disabled drive brakes to rest and drops its set-point
        return super().step(dt)


@dataclass
class Memory:
    """A block of node memory reachable with DDS/DUS."""

    data: bytearray
    writable: bool


@dataclass
class _Download:
    node_id: int
    memory_id: int
    numbers: range  # the message codes the data messages must carry, in order
    received: int = 0
    data: bytearray = field(default_factory=bytearray)


SCRATCH_MEMORY_ID = 1  # 64 bytes of writable scratch memory in the turret node
IDENT_MEMORY_ID = 16  # read-only identification text


@dataclass
class SimConfig:
    turret_node_id: int = TURRET_NODE_ID
    zoom_position_id: int = DEFAULT_ZOOM_POSITION_ID
    fps_security_code: int = DEFAULT_FPS_SECURITY_CODE
    yaw_max_velocity: float = 60.0
    pitch_max_velocity: float = 40.0
    acceleration: float = 180.0
    pitch_min: float = -30.0
    pitch_max: float = 60.0
    hardware_revision: int = 2
    software_revision: int = 7
    latitude_deg: float = 48.1372
    longitude_deg: float = 11.5756
    altitude_m: float = 519.0
    pad_frames: bool = False
    # Answer every TIS with -6 (out of range), like a turret with fixed intervals.
    refuse_tis: bool = False
    # DDS/DUS data messages count from 0 (default) or 1 (the ICD does not say)
    transfer_first_number: int = ns.DEFAULT_FIRST_NUMBER
    intervals_ms: dict[str, int] = field(default_factory=lambda: dict(DEFAULT_INTERVALS_MS))
