"""canaero_turret_sim: the command line (arguments, the JSON ready line, the console)."""

from __future__ import annotations

import argparse
import logging
import os

import can

from gimbal_driver_common.sim_control import run_simulator
from gimbal_driver_common.sim_server import PtySimServer, TcpSimServer

from ..protocol import nodeservice as ns
from ..protocol.identifiers import DEFAULT_ZOOM_POSITION_ID, TURRET_NODE_ID
from ..slcan import open_bus
from .axis import DEFAULT_FPS_SECURITY_CODE, SimConfig
from .control import make_control
from .model import TurretSimulator
from .transport import BusSimRunner, SlcanSession, SocketcandSession


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="canaero_turret_sim",
        description="CANaerospace turret simulator (turret, cover, GNSS and zoom nodes).")
    parser.add_argument("--transport", choices=("slcan-pty", "socketcand", "bus"),
                        default="slcan-pty",
                        help="slcan over a pseudo-terminal (default), a socketcand-style TCP "
                             "bridge on 127.0.0.1, or a python-can bus")
    parser.add_argument("--port", type=int, default=0,
                        help="TCP port of the socketcand bridge on 127.0.0.1 (0 = any)")
    parser.add_argument("--link", default=None,
                        help="path of the pty symlink for slcan-pty (default: a temp path)")
    parser.add_argument("--interface", default="virtual",
                        help="python-can interface for --transport bus (e.g. socketcan)")
    parser.add_argument("--channel", default="vcan0", help="python-can channel for bus")
    parser.add_argument("--control-port", type=int, default=0,
                        help="control console on 127.0.0.1 (0 = any free port, -1 = none); "
                             "the same verbs are read on stdin")
    parser.add_argument("--turret-node-id", type=int, default=TURRET_NODE_ID)
    parser.add_argument("--zoom-position-id", type=int, default=DEFAULT_ZOOM_POSITION_ID)
    parser.add_argument("--fps-security-code", type=int, default=DEFAULT_FPS_SECURITY_CODE)
    parser.add_argument("--refuse-tis", action="store_true",
                        help="answer every TIS request with -6 (fixed transmission intervals)")
    parser.add_argument("--transfer-first-number", type=int, choices=ns.FIRST_NUMBERS,
                        default=ns.DEFAULT_FIRST_NUMBER,
                        help="number of the first DDS/DUS data message (default 0)")
    parser.add_argument("--pad-frames", action="store_true",
                        help="send 8-byte frames (zero padded) like the ICD examples")
    parser.add_argument("--ready-file", default=None,
                        help="also write the JSON ready line to this file")
    parser.add_argument("-v", "--verbose", action="store_true")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    config = SimConfig(turret_node_id=args.turret_node_id,
                       zoom_position_id=args.zoom_position_id,
                       fps_security_code=args.fps_security_code, pad_frames=args.pad_frames,
                       refuse_tis=args.refuse_tis,
                       transfer_first_number=args.transfer_first_number)
    simulator = TurretSimulator(config)
    link: PtySimServer | TcpSimServer | None = None
    runner = None
    bus = None
    endpoint: dict[str, object]
    if args.transport == "slcan-pty":
        pty = PtySimServer(lambda: SlcanSession(simulator), link_path=args.link).start()
        link = pty
        endpoint = {"interface": "slcan", "channel": pty.port_name, "pty": pty.port_name}
    elif args.transport == "socketcand":
        hub = f"canaero-sim-hub-{os.getpid()}"
        bus = can.Bus(interface="virtual", channel=hub)
        runner = BusSimRunner(simulator, bus).start()
        tcp = TcpSimServer(lambda: SocketcandSession(hub), port=args.port).start()
        link = tcp
        endpoint = {"interface": "socketcand", "channel": "can0", "host": tcp.host,
                    "port": tcp.port}
    else:
        bus = open_bus(args.interface, args.channel)
        runner = BusSimRunner(simulator, bus).start()
        endpoint = {"interface": args.interface, "channel": args.channel}
    try:
        run_simulator(make_control(simulator, link), endpoint, args.control_port,
                      ready_file=args.ready_file)
    finally:
        if link is not None:
            link.stop()
        if runner is not None:
            runner.stop()
        if bus is not None:
            bus.shutdown()
    return 0
