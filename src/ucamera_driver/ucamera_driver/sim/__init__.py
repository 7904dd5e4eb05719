"""U-Camera simulator: speaks UCSP on a pseudo-terminal (``ucamera_sim``).

The device model follows chapter 4 and 5 of the user manual:

* power-up: INIT mode, points to pan 0 / tilt 0, then ANGLES mode (4.1);
* ANGLES slews to the commanded angles, RATES integrates the commanded rates,
  STOW goes to pan 0 / tilt +90, PILOT to pan 0 / tilt 0 (4.2);
* GYRO/FULL AUTOALIGN point to 0/0, hold still for a while, then switch to
  ANGLES (4.6); FFC CALIBRATION (IR gimbals only) points to pan 0 / tilt 90,
  calibrates and switches to ANGLES (4.7). After these the angles target is the
  last commanded angles;
* Set Angles / Set Rates take effect only in their own mode (5.5.3.3, 5.5.3.5);
* every periodic report (reconstructed 5.6, ``PERIODIC_REPORTS``) is sent at
  the telemetry rate (1..200 Hz); requests are answered before the next reports;
* Save Configuration makes the gimbal silent and deaf for ``save_pause`` s
  (5.5.1.1) and stores telemetry rate, antenna position, GPS feed and palette
  (``nv``); Save FFC is counted (IR only).

Motion: each axis runs on the shared trapezoidal model
(``gimbal_driver_common.sim_motion``), accelerating at ``acceleration`` up to ``max_rate``,
and stops at its mechanical limits (pan +-180 deg, tilt -90..+90 deg: the manual gives no
figures, these are simulator assumptions, see the README).

Faults (API, CLI flags, and the shared control verbs of
``gimbal_driver_common.sim_control`` on stdin and the TCP console): garbage/noise bytes,
silence, corrupted bytes in outgoing frames, dropped outgoing frames, link drop (pty
destroyed and recreated behind the same path). UCSP has no NACK and no fault register:
``nack`` and ``fault`` answer why.

Modules: ``model`` (the device: modes, motion, zoom, periodic reports), ``handlers`` (the
received commands and requests), ``transport`` (faults on sent frames, the pty session, the
simulator and its console), ``cli`` (``ucamera_sim``).
"""

from .cli import build_arg_parser, config_from_args, main
from .handlers import CommandHandlers
from .model import (
    AUTOMATIC_MODES,
    FFC_POSITION,
    PAN_LIMITS,
    PILOT_POSITION,
    STOW_POSITION,
    TILT_LIMITS,
    SimConfig,
    UCameraModel,
)
from .transport import Faults, UCameraSession, UCameraSim

__all__ = [
    'AUTOMATIC_MODES', 'FFC_POSITION', 'PAN_LIMITS', 'PILOT_POSITION', 'STOW_POSITION',
    'TILT_LIMITS', 'CommandHandlers', 'Faults', 'SimConfig', 'UCameraModel', 'UCameraSession',
    'UCameraSim', 'build_arg_parser', 'config_from_args', 'main',
]
