"""``ros2 run gimbal_driver_common gimbal_probe``: the command line of :mod:`.probe` (no ROS).

Exit status: 0 a device answered (its parameters printed, and written with ``--output``),
1 nothing answered (what was tried is printed), 2 bad arguments or a file not written.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

import yaml

from gimbal_driver_common.probe import (
    Found,
    Outcome,
    ProbeLink,
    Report,
    registered_probes,
    run_probes,
)
from gimbal_driver_common.registry import RegistryError

EXIT_FOUND, EXIT_NOTHING, EXIT_USAGE = 0, 1, 2


def parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='gimbal_probe',
        description='Find which gimbal or pedestal answers on a serial port, a TCP host or a '
                    'CAN bus, and how, using only requests that read (nothing moves, nothing '
                    'is written). Prints what answered and a params_file for its driver.')
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument('--serial', metavar='PORT',
                       help='a serial port, e.g. /dev/ttyUSB0 (each device\'s documented baud '
                            'rates are tried, most likely first)')
    where.add_argument('--tcp', metavar='HOST[:PORT]',
                       help='a TCP host, with a port or without (then each device\'s '
                            'documented port)')
    where.add_argument('--can', metavar='CHANNEL',
                       help='a CAN channel, e.g. can0 or the serial port of an slcan adapter')
    parser.add_argument('--can-interface', default='socketcan', metavar='NAME',
                        help='python-can interface of --can (socketcan, slcan, ...; default '
                             '%(default)s)')
    parser.add_argument('--can-bitrate', type=int, default=0, metavar='N',
                        help='CAN bit rate to set on the adapter (0: keep the interface\'s)')
    parser.add_argument('--password', default='',
                        help='device password for a handshake that needs one (Kessler kOS); '
                             'never printed')
    parser.add_argument('--timeout', type=float, default=1.0, metavar='S',
                        help='seconds each attempt waits for answers (default %(default)s)')
    parser.add_argument('--output', metavar='FILE',
                        help='write the parameters of what answered here (the driver launch '
                             'file\'s params_file)')
    return parser


def link_from(args: argparse.Namespace) -> ProbeLink:
    """The :class:`ProbeLink` of parsed arguments; ValueError with the reason."""
    common = {'password': args.password, 'timeout': args.timeout}
    if args.serial:
        return ProbeLink('serial', serial_port=args.serial, **common)
    if args.tcp:
        host, port = split_host_port(args.tcp)
        return ProbeLink('tcp', host=host, port=port, **common)
    if args.can_bitrate < 0:
        raise ValueError(f'--can-bitrate must be >= 0, not {args.can_bitrate}')
    return ProbeLink('can', can_channel=args.can, can_interface=args.can_interface,
                     can_bitrate=args.can_bitrate, **common)


def split_host_port(text: str) -> tuple[str, int]:
    """``HOST``, ``HOST:PORT`` or ``[V6]:PORT`` -> (host, port or 0)."""
    if text.startswith('['):
        host, _, rest = text[1:].partition(']')
        port_text = rest.removeprefix(':')
    elif text.count(':') == 1:
        host, _, port_text = text.partition(':')
    else:
        host, port_text = text, ''
    if not host:
        raise ValueError(f'--tcp {text!r} names no host')
    if not port_text:
        return host, 0
    if not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise ValueError(f'--tcp {text!r}: the port must be a number 1..65535')
    return host, int(port_text)


def parameters_yaml(found: Sequence[Found]) -> str:
    """A ROS 2 parameters file the launch's ``params_file`` applies under any namespace:
    ``/**: ros__parameters: {...}`` for one device (any node name, as config/*.yaml), and
    ``/**/<node_name>:`` per device when several answered, so each keeps its own values
    (rclpy matches a key's ``/**`` against any run of names of the node's full name:
    rclpy/src/rclpy/node.cpp ``_populate_node_parameters_from_rcl_params``)."""
    document: dict[str, Any] = {}
    for device in found:
        key = '/**' if len(found) == 1 else f'/**/{device.node_name}'
        document[key] = {'ros__parameters': dict(device.parameters)}
    return yaml.safe_dump(document, sort_keys=False, default_flow_style=False)


def print_outcome(outcome: Outcome, out: TextIO) -> None:
    verdict = 'ANSWERED' if outcome.found is not None else f'no: {outcome.reason}'
    print(f'  {outcome.driver:<16} {outcome.settings}: {verdict}', file=out, flush=True)


def print_found(device: Found, out: TextIO) -> None:
    print(f'\nFound: {device.device} ({device.driver} driver, node {device.node_name})',
          file=out)
    print(f'  protocol: {device.protocol}', file=out)
    rows = [('link', device.link), ('ids', device.ids), ('identity', device.identity)]
    for label, values in rows:
        if values:
            text = ', '.join(f'{k} {v}' for k, v in values.items())
            print(f'  {label}: {text}', file=out)
    for note in device.notes:
        print(f'  note: {note}', file=out)


def print_summary(report: Report, out: TextIO) -> None:
    found = report.found
    if not found:
        tried = '; '.join(f'{o.driver} {o.settings}' for o in report.outcomes) or 'nothing'
        print(f'\nNo device answered on {report.link.describe()}. Tried: {tried}.', file=out)
        return
    for device in found:
        print_found(device, out)
    print('\nParameters (the driver launch file\'s params_file):', file=out)
    print(parameters_yaml(found), file=out, end='')


def main(argv: Sequence[str] | None = None, out: TextIO | None = None) -> int:
    out = out or sys.stdout
    args = parser().parse_args(argv)
    # the clients' own log lines (a reconnect warning, a silence) would repeat what each
    # attempt's line says; only errors get through
    logging.basicConfig(level=logging.ERROR, format='gimbal_probe: %(name)s: %(message)s')
    try:
        link = link_from(args)
    except ValueError as exc:
        print(f'gimbal_probe: {exc}', file=sys.stderr)
        return EXIT_USAGE
    try:
        probes = registered_probes()
    except RegistryError as exc:
        print(f'gimbal_probe: {exc}', file=sys.stderr)
        return EXIT_USAGE
    if not probes:
        print('gimbal_probe: no installed driver registers a probe', file=sys.stderr)
        return EXIT_NOTHING
    print(f'Probing {link.describe()} (read-only; {args.timeout:g} s per attempt):', file=out,
          flush=True)
    report = run_probes(link, probes, on_outcome=lambda o: print_outcome(o, out))
    print_summary(report, out)
    if not report.found:
        return EXIT_NOTHING
    if args.output:
        try:
            Path(args.output).write_text(parameters_yaml(report.found), encoding='utf-8')
        except OSError as exc:
            print(f'gimbal_probe: cannot write {args.output}: {exc}', file=sys.stderr)
            return EXIT_USAGE
        print(f'\nWrote {args.output}', file=out)
    return EXIT_FOUND


if __name__ == '__main__':
    sys.exit(main())
