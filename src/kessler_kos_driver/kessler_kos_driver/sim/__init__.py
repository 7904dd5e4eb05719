"""Kessler kOS CineShooter simulator: the kOS network protocol on TCP 127.0.0.1.

What it models (document sections in brackets):
- motors (slider, pan, tilt by default; focus/zoom optional) with trapezoidal speed/acceleration
  physics in rotations, the documented maxima, MotorPosition when a motor becomes idle;
- calibration (MarkBegin/MarkEnd/ResetAxis, MotorCalibrated);
- password lock (UserPassword/DevicePassword; a locked device ignores most messages and
  answers a wrong password with ErrorStatus 15);
- the 30 s keep-alive: a connection silent for `keepalive_timeout` seconds is dropped;
- discovery: NetworkInfo datagrams every 5 s while no client is connected, sent to 127.0.0.1
  only (never broadcast), to `discovery_port`;
- TrajectoryData storage and validation (ErrorStatus 3), Bezier playback over time with the
  documented PlaybackStatus sequences for Live Motion (loops, reverse, rapid reverse) and
  Time Lapse (continuous and shoot-move-shoot, pre/post photos, photo counting);
- UnsupportedMessage for anything the document does not define;
- LEDStatus and SoftwareID (Get/Set), AuxInputStatus notifications (control command `aux`);
- the USB face (document "USB Notes"): `SimHidDevice` has the methods of cython-hidapi's
  `hid.device` and carries the same device model in 64-byte reports with report ID 0x01, so
  the client's USB transport runs end to end in-process; a USB session needs no password
  (UserPassword/DevicePassword get UnsupportedMessage) and takes the six-byte keep-alive;
- motion on the shared trapezoidal model (``gimbal_driver_common.sim_motion``);
- fault injection: link drop, motor offline/online, axis fault (ErrorStatus 16 + reset),
  garbage bytes, silence; from Python or with the shared control verbs
  (``gimbal_driver_common.sim_control``) on stdin and the TCP console on 127.0.0.1.

Simulated time runs `time_scale` times faster than wall time (durations, delays, exposures and
physics); keep-alive and discovery periods are wall-clock.

Modules: ``motor`` (constants, one motor, the settings), ``model`` (the device: motors,
playback over time, replies, faults), ``handlers`` (the client messages), ``transport``
(a TCP or USB session, the HID device, the TCP simulator and its console), ``cli``
(``kessler_kos_sim``).
"""

from .cli import build_arg_parser, main
from .handlers import MessageHandlers
from .model import SimulatedRig
from .motor import (
    ALLOWED_WHILE_LOCKED,
    DEFAULT_RANGES,
    MAX_CATCH_UP_S,
    PHYSICS_STEP_S,
    SimMotor,
    SimSettings,
)
from .transport import KosSession, KosSimulator, SimHidDevice, control

__all__ = [
    'ALLOWED_WHILE_LOCKED', 'DEFAULT_RANGES', 'MAX_CATCH_UP_S', 'PHYSICS_STEP_S', 'KosSession',
    'KosSimulator', 'MessageHandlers', 'SimHidDevice', 'SimMotor', 'SimSettings',
    'SimulatedRig', 'build_arg_parser', 'control', 'main',
]
