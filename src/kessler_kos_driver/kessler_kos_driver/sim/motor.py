"""kOS simulator: physics constants, one motor, the settings and the playback state."""

from __future__ import annotations

from dataclasses import dataclass, field

from gimbal_driver_common.sim_motion import AxisMotion

from ..protocol import (
    KEEPALIVE_DROP_S,
    UNCALIBRATED_TARGET,
    DeviceType,
    GetDeviceInfo,
    GetNetworkInfo,
    PlaybackState,
    Trajectory,
    UserPassword,
)

PHYSICS_STEP_S = 0.002          # simulated seconds per integration step
MAX_CATCH_UP_S = 5.0            # simulated seconds integrated at most per advance()
DEFAULT_RANGES = {'slider': 200.0, 'pan': 100.0, 'tilt': -40.0, 'focus': 10.0, 'zoom': 10.0}
# Locked devices still answer these (identification, keep-alive, unlocking).
ALLOWED_WHILE_LOCKED = (GetDeviceInfo, GetNetworkInfo, UserPassword)


@dataclass
class SimMotor(AxisMotion):
    """One motor in rotations on the shared trapezoidal model (``AxisMotion``); its travel
    is the calibrated range (or +-UNCALIBRATED_TARGET before calibration)."""

    address: int = 1
    role: str = 'pan'
    begin: float = 0.0
    end: float = 0.0                  # 0 = uncalibrated
    mark_begin_raw: float | None = None
    online: bool = True
    max_setup_speed: float = 0.0
    max_move_speed: float = 0.0
    max_acceleration: float = 0.0

    @property
    def is_fiz(self) -> bool:
        return self.role in ('focus', 'zoom')

    @property
    def calibrated(self) -> bool:
        return self.end != 0.0

    def travel_limits(self) -> tuple[float, float]:
        if self.calibrated:
            return min(0.0, self.end), max(0.0, self.end)
        return -UNCALIBRATED_TARGET, UNCALIBRATED_TARGET

    def clamp(self, position: float) -> float:
        low, high = self.travel_limits()  # follows calibration as it changes
        return min(max(position, low), high)

    def command(self, target: float, speed: float, acceleration: float) -> None:
        """SetPositionSpeedAcceleration: speed and acceleration capped at the maxima;
        speed 0 decelerates to a stop where the motor can."""
        speed = min(max(speed, 0.0), self.max_setup_speed)
        accel = acceleration if acceleration > 0 else self.max_acceleration
        self.acceleration = min(accel, self.max_acceleration)
        if speed == 0.0:
            self.stop()
        else:
            self.move_to(target, speed)

    def halt_now(self) -> None:
        self.stop(immediate=True)


@dataclass
class SimSettings:
    password: str = ''
    motors: tuple[str, ...] = ('slider', 'pan', 'tilt')
    precalibrated: bool = False
    time_scale: float = 1.0
    keepalive_timeout: float = KEEPALIVE_DROP_S
    device_type: int = DeviceType.CINESHOOTER
    guid: bytes = bytes.fromhex('4b4f53000000000000000000c1e55100')
    firmware: tuple[int, int, int, int] = (2, 4, 1, 7)


@dataclass
class _Playback:
    """Device-side playback state machine."""

    trajectory: Trajectory | None = None
    phase: str = 'idle'      # idle, homing, ready, delay, pre_photos, play, sms, post_photos
    setup_done: bool = False
    direction: int = 1
    loops_left: int = 0
    loop_forever: bool = False
    move_time: float = 0.0   # simulated seconds into the current pass
    curve_dt: float = 0.0    # simulated seconds since the playing axes were set on the curve
    pass_length: float = 0.0
    elapsed: float = 0.0     # normalised
    photos: int = 0
    phase_time: float = 0.0
    photos_in_phase: int = 0
    sms_frame: int = 0
    sms_step: str = ''
    start_after_homing: bool = False
    homing_owed: bool = False   # SetupPlayback(DelayReturn): return after StartPlayback
    homing_targets: dict[int, float] = field(default_factory=dict)
    start_at: float | None = None   # DelayMode 2: wall-clock UnixTime the move starts at
    status: int = PlaybackState.NO_MOVE
