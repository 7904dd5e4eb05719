"""capture_sim: the command line (arguments, the JSON ready line, the console)."""

from __future__ import annotations

import argparse
import logging

from gimbal_driver_common.sim_control import run_simulator

from ..protocol import COMMANDS
from .axis import KNOWN_SETS, command_names
from .model import PedestalModel
from .transport import CaptureSimulator


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog='capture_sim',
        description='Capture pedestal simulator on 127.0.0.1 (TCP) and/or a pseudo-terminal.',
    )
    parser.add_argument('--port', type=int, default=4949,
                        help='TCP port on 127.0.0.1 (0 = any free port, -1 = no TCP)')
    parser.add_argument('--pty', action='store_true', help='also serve a pseudo-terminal')
    parser.add_argument('--pty-link', default=None, help='stable symlink path for the pty')
    parser.add_argument('--axes', type=int, default=2, choices=(2, 3))
    parser.add_argument('--no-gps', action='store_true', help='simulate a system without GPS')
    parser.add_argument('--no-imu', action='store_true', help='simulate a manual system')
    parser.add_argument('--no-digital-io', action='store_true',
                        help='firmware before 2.22.0: no COM_set/getDigitalIO')
    parser.add_argument('--gear-ratio', type=float, default=1.0)
    parser.add_argument('--time-scale', type=float, default=1.0,
                        help='simulated seconds per real second (faster tests)')
    parser.add_argument('--control-port', type=int, default=0,
                        help='control console on 127.0.0.1 (0 = any free port, -1 = none); '
                             'the same verbs are read on stdin')
    parser.add_argument('--unknown', action='append', default=[], metavar='COMMAND',
                        help='play a device that does not know this table command: it '
                             'answers 0xA6 "Opcode not Recognized" (repeatable)')
    parser.add_argument('--only', action='append', default=None, metavar='NAMES',
                        help='play a device that knows only these table commands (comma-'
                             'separated, repeatable; the sets ' + ', '.join(KNOWN_SETS)
                             + ' name what partial controllers know); the rest get 0xA6, '
                             'or an ACK with --ack-unknown')
    parser.add_argument('--ack-unknown', action='store_true',
                        help='answer ACK (0x06) instead of NACK 0xA6 to every opcode the '
                             'device does not know, getters included (a third-party '
                             'controller)')
    parser.add_argument('--one-request-per-read', action='store_true',
                        help='play a controller that drops every packet after the first in '
                             'one receive (the driver then reads one request at a time)')
    parser.add_argument('--nagle', action='store_true',
                        help='play a controller whose TCP stack leaves Nagle\'s algorithm on '
                             'and writes each reply in its own segment')
    parser.add_argument('--log-level', default='INFO')
    args = parser.parse_args(argv)
    for name in args.unknown:
        if name not in COMMANDS:
            parser.error(f'--unknown {name}: not a command of the table')
    known = None
    if args.only is not None:
        try:
            known = command_names(n.strip() for arg in args.only for n in arg.split(',')
                                  if n.strip())
        except KeyError as exc:
            parser.error(f'--only: {exc.args[0]}')
    logging.basicConfig(level=args.log_level.upper(), format='%(name)s: %(message)s')
    model = PedestalModel(axes=args.axes, gps=not args.no_gps, imu=not args.no_imu,
                          gear_ratio=args.gear_ratio, time_scale=args.time_scale,
                          unknown_commands=args.unknown, known_commands=known,
                          ack_unknown=args.ack_unknown)
    model.digital_io_present = not args.no_digital_io
    model.one_request_per_read = args.one_request_per_read
    sim = CaptureSimulator(model, tcp_port=None if args.port < 0 else args.port,
                           pty=args.pty, pty_link=args.pty_link, nagle=args.nagle)
    sim.start()
    try:
        run_simulator(sim.controls, {'port': sim.tcp.port if sim.tcp else None,
                                     'pty': sim.pty.port_name if sim.pty else None},
                      args.control_port)
    finally:
        sim.stop()
    return 0
