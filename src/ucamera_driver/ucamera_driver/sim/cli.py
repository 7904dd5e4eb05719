"""ucamera_sim: the command line (arguments, the JSON ready line, the console)."""

from __future__ import annotations

import argparse
import logging
import math
import sys

from gimbal_driver_common.sim_control import run_simulator

from ..protocol import GimbalType
from .model import SimConfig
from .transport import UCameraSim

LOG = logging.getLogger("ucamera_sim")


def build_arg_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ucamera_sim",
        description="Airelectronics U-Camera simulator on a pseudo-terminal (UCSP, 115200 8N1). "
        "Prints a JSON ready line with the serial port path to open; reads control verbs on "
        "stdin and on a TCP console (type help).",
    )
    parser.add_argument("--link", default=None,
                        help="stable symlink to create for the pty (default: a temp path)")
    parser.add_argument("--gimbal-type", choices=["ir", "daylight"], default="ir")
    parser.add_argument("--telemetry-rate", type=int, default=50, help="Hz, 1..200")
    parser.add_argument("--max-rate", type=float, default=60.0, help="deg/s per axis")
    parser.add_argument("--acceleration", type=float, default=240.0, help="deg/s^2")
    parser.add_argument("--init-time", type=float, default=0.5, help="s in INIT at power-up")
    parser.add_argument("--autoalign-time", type=float, default=2.0, help="s")
    parser.add_argument("--ffc-time", type=float, default=1.0, help="s")
    parser.add_argument("--save-pause", type=float, default=1.0,
                        help="s of silence after Save Configuration")
    parser.add_argument("--noise-rate", type=float, default=0.0, help="garbage bytes/s")
    parser.add_argument("--corrupt-rate", type=float, default=0.0,
                        help="probability that a sent frame gets one bit flipped")
    parser.add_argument("--drop-rate", type=float, default=0.0,
                        help="probability that a sent frame is lost")
    parser.add_argument("--control-port", type=int, default=0,
                        help="control console on 127.0.0.1 (0 = any free port, -1 = none); "
                             "the same verbs are read on stdin")
    parser.add_argument("--log-level", default="INFO")
    return parser


def config_from_args(args: argparse.Namespace) -> SimConfig:
    if not 1 <= args.telemetry_rate <= 200:
        raise SystemExit("--telemetry-rate must be within 1..200 Hz")
    return SimConfig(
        gimbal_type=GimbalType.IR if args.gimbal_type == "ir" else GimbalType.DAYLIGHT,
        telemetry_rate=args.telemetry_rate,
        max_rate=math.radians(args.max_rate),
        acceleration=math.radians(args.acceleration),
        init_time=args.init_time,
        autoalign_time=args.autoalign_time,
        ffc_time=args.ffc_time,
        save_pause=args.save_pause,
    )


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--ros-args" in argv:  # started by a ROS launch file: those arguments are not ours
        argv = argv[: argv.index("--ros-args")]
    args = build_arg_parser().parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(name)s: %(message)s")
    sim = UCameraSim(config_from_args(args), link_path=args.link)
    sim.set_noise_rate(args.noise_rate)
    sim.corrupt(probability=args.corrupt_rate)
    sim.drop_frames(args.drop_rate)
    try:
        sim.start()
    except OSError as exc:
        raise SystemExit(f"ucamera_sim: cannot create the pseudo-terminal link "
                         f"{args.link or ''}: {exc}") from exc
    LOG.info("U-Camera simulator serving on %s", sim.port_name)
    try:
        run_simulator(sim.controls, {"pty": sim.port_name}, args.control_port)
    finally:
        sim.stop()
    return 0
