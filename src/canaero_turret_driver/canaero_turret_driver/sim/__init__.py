"""CANaerospace turret simulator: turret, cover, GNSS and zoom nodes on one CAN bus.

The model (`TurretSimulator`) turns received CAN frames into replies and produces the
periodic NOD broadcasts. It is reached in one of two ways:

* `BusSimRunner`: on any python-can bus (`virtual` inside one process for tests,
  `socketcan` on a vcan interface on a robot);
* `SlcanSession` behind the shared `PtySimServer`: the simulator speaks the slcan ASCII
  protocol (Lawicel) on a pseudo-terminal, so another process opens it with
  python-can's `slcan` interface (`channel=<pty path>`). This is how the node tests and
  `canaero_turret_sim` work on machines without SocketCAN.

Axes run on the shared trapezoidal model (`gimbal_driver_common.sim_motion`). Fault
injection (methods of `TurretSimulator`, and the shared control verbs of
`gimbal_driver_common.sim_control` on stdin and the `--control-port` console, see
`make_control`): silence the nodes or one node, lose or repeat NOD frames (message-code
gaps), malformed frames, EED events, axis drive faults, periphery faults; `drop` and
`garbage` cut the link or send garbage bytes.

Simulator-defined EED codes (the ICD defines none): see `EedCode`. Operation id = the
offending command (`Operation`), location id = 1 yaw, 2 pitch, 0 whole node.

Modules: ``axis`` (constants, EED codes, one drive, the configuration), ``model`` (the
device: state, NOD broadcasts, fault injection), ``handlers`` (commands and node services),
``transport`` (bus runner, slcan and socketcand sessions), ``control`` (the console verbs),
``cli`` (``canaero_turret_sim``).
"""

from gimbal_driver_common.sim_control import ControlClient, ControlServer

from .axis import (
    DEFAULT_FPS_SECURITY_CODE,
    DEFAULT_INTERVALS_MS,
    IDENT_MEMORY_ID,
    LOCATION,
    MAX_INTERVAL_MS,
    MIN_INTERVAL_MS,
    PITCH,
    SCRATCH_MEMORY_ID,
    SETPOINTS,
    SWITCHES,
    YAW,
    AxisModel,
    EedCode,
    Memory,
    Operation,
    SimConfig,
)
from .cli import build_parser, main
from .control import FAULT_NAMES, make_control
from .model import TurretSimulator
from .transport import (
    BusSimRunner,
    SlcanSession,
    SocketcandSession,
    encode_slcan,
    encode_socketcand,
)

__all__ = [
    'DEFAULT_FPS_SECURITY_CODE', 'DEFAULT_INTERVALS_MS', 'FAULT_NAMES', 'IDENT_MEMORY_ID',
    'LOCATION', 'MAX_INTERVAL_MS', 'MIN_INTERVAL_MS', 'PITCH', 'SCRATCH_MEMORY_ID', 'SETPOINTS',
    'SWITCHES', 'YAW', 'AxisModel', 'BusSimRunner', 'ControlClient', 'ControlServer', 'EedCode',
    'Memory', 'Operation', 'SimConfig', 'SlcanSession', 'SocketcandSession', 'TurretSimulator',
    'build_parser', 'encode_slcan', 'encode_socketcand', 'main', 'make_control',
]
