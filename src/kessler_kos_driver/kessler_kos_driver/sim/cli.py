"""kessler_kos_sim: the command line (arguments, the JSON ready line, the console)."""

from __future__ import annotations

import argparse
import logging
import sys

from gimbal_driver_common.sim_control import run_simulator

from ..protocol import (
    DEFAULT_TCP_PORT,
    DOCUMENTED_MAXIMA,
    KEEPALIVE_DROP_S,
    MOTOR_ADDRESS_MAX,
    MOTOR_ADDRESS_MIN,
)
from .motor import SimSettings
from .transport import KosSimulator


def build_arg_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='kessler_kos_sim',
        description='Kessler kOS CineShooter simulator on TCP 127.0.0.1 (kOS network protocol).')
    parser.add_argument('--port', type=int, default=DEFAULT_TCP_PORT,
                        help='TCP port on 127.0.0.1 (0 = any free port; default 5520)')
    parser.add_argument('--password', default='', help='device password (default empty)')
    parser.add_argument('--motors', default='slider,pan,tilt',
                        help='comma-separated motor roles in address order '
                             '(slider, pan, tilt, focus, zoom); default slider,pan,tilt')
    parser.add_argument('--precalibrated', action='store_true',
                        help='start with every motor calibrated over a default range')
    parser.add_argument('--time-scale', type=float, default=1.0,
                        help='simulated seconds per wall-clock second (default 1)')
    parser.add_argument('--keepalive-timeout', type=float, default=KEEPALIVE_DROP_S,
                        help='drop a connection silent for this many wall seconds (30)')
    parser.add_argument('--discovery-port', type=int, default=DEFAULT_TCP_PORT,
                        help='UDP port NetworkInfo beacons go to on 127.0.0.1 (0 = off)')
    parser.add_argument('--control-port', type=int, default=0,
                        help='control console on 127.0.0.1 (0 = any free port, -1 = none); '
                             'the same verbs are read on stdin')
    parser.add_argument('--verbose', action='store_true')
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_arg_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format='%(asctime)s %(name)s: %(message)s')
    roles = tuple(r.strip().lower() for r in args.motors.split(',') if r.strip())
    unknown = [r for r in roles if r not in DOCUMENTED_MAXIMA]
    if not roles or unknown or len(roles) > MOTOR_ADDRESS_MAX - MOTOR_ADDRESS_MIN + 1:
        print(f'kessler_kos_sim: --motors must list 1..10 of {sorted(DOCUMENTED_MAXIMA)}, '
              f'got {args.motors!r}', file=sys.stderr)
        return 2
    if args.time_scale <= 0 or args.keepalive_timeout <= 0:
        print('kessler_kos_sim: --time-scale and --keepalive-timeout must be > 0',
              file=sys.stderr)
        return 2
    settings = SimSettings(password=args.password, motors=roles,
                           precalibrated=args.precalibrated, time_scale=args.time_scale,
                           keepalive_timeout=args.keepalive_timeout)
    sim = KosSimulator(settings, port=args.port, discovery_port=args.discovery_port)
    try:
        sim.start()
    except OSError as exc:
        print(f'kessler_kos_sim: cannot listen on 127.0.0.1:{args.port}: {exc}',
              file=sys.stderr)
        return 1
    try:
        run_simulator(sim.controls, {'port': sim.port, 'motors': list(roles)},
                      args.control_port)
    finally:
        sim.stop()
    return 0
