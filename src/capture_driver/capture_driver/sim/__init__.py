"""Capture pedestal simulator: the wire protocol over TCP (127.0.0.1) and a pseudo-terminal.

The model (:class:`PedestalModel`) is one physical pedestal shared by every connection, as
the real controller is: motion physics per axis (absolute/relative position mode and
speed mode, MOT_Update semantics, speed and acceleration ramps, software and hardware
limit switches, axis on/off, emergency stop), homing, the three device scan patterns,
15 presets with looping, GPS targets and go-to-target, IMU angles and rates, the
keep-alive supervision, and registers (MER, DER, SRH, SRL, MSR, CMER, CSR, operation,
system state) whose bits follow the motion.

Axes run on the shared trapezoidal model (``gimbal_driver_common.sim_motion``). Fault
injection (methods of :class:`PedestalModel`, and the shared control verbs of
``gimbal_driver_common.sim_control`` on stdin and the ``--control-port`` console: drop,
silence, garbage, nack, fault, ignore_motion, mute, delay, clear, state, quit, plus
Capture's lose, unknown, wrong, pose, detect, dio, count): latched axis and system faults,
NACK replies, lost replies, garbage bytes, a silent device and a dropped link, replies of
the wrong kind (``wrong``), a command never answered (``mute``) or answered late
(``delay``: the session holds the reply, an ACK byte or a data packet). A device
that knows only part of the table (``known_commands`` / ``--only``, ``unknown_commands`` /
``--unknown``) answers the rest with NACK 0xA6, or with an ACK (``ack_unknown`` /
``--ack-unknown``) as a third-party controller does.

The device is a table of opcodes, and so is the model: :data:`HANDLERS` maps every command
it executes to its handler, one row each (a table command without a row stores and returns
its value); handlers longer than a row are methods of :class:`PedestalModel`.

Modules: ``axis`` (fault names, device constants, one motor axis), ``model`` (the pedestal:
state, motion, fault injection, request execution), ``handlers`` (the handlers longer than a
table row), ``table`` (:data:`HANDLERS`), ``transport`` (one connection's byte stream and
the TCP and pty servers with the control console), ``cli`` (``capture_sim``).

Assumptions where the spec is silent are marked "sim:" in comments.
"""

from .axis import (
    FAULTS,
    GYRO_BIAS,
    KNOWN_SETS,
    SYSTEM_FAULTS,
    AxisModel,
    RequestRejected,
    ScanState,
    command_names,
)
from .cli import main
from .model import PedestalModel
from .table import HANDLERS, Handler
from .transport import CaptureSession, CaptureSimulator, console_state, control

__all__ = [
    'FAULTS', 'GYRO_BIAS', 'HANDLERS', 'KNOWN_SETS', 'SYSTEM_FAULTS', 'AxisModel',
    'CaptureSession', 'CaptureSimulator', 'Handler', 'PedestalModel', 'RequestRejected',
    'ScanState', 'command_names', 'console_state', 'control', 'main',
]
