"""Turret simulator: the control console verbs (shared ones plus the turret's own)."""

from __future__ import annotations

import math

from gimbal_driver_common.sim_control import ControlError, Link, SimControl

from .axis import YAW
from .model import REQUESTS, TurretSimulator

FAULT_NAMES = ("drive", "case_sensor")


def make_control(simulator: TurretSimulator, link: Link | None = None) -> SimControl:
    """The shared control verbs for the turret plus its own (``link``: the PtySimServer or
    TcpSimServer the simulator is reached through; None on a python-can bus).

    ``silence on|off`` silences every CAN node (the slcan adapter keeps answering, as a
    real adapter on a bus whose nodes went quiet); ``fault drive [yaw|pitch]`` trips a
    drive (EED + disabled axis), ``fault case_sensor`` the periphery's case sensor.
    Device verbs: node_silence, lose, repeat, malformed, eed. ``mute``/``delay`` take the
    node services the nodes answer (IDS, DDS, DUS, TIS, FPS, NIS).
    """

    def silence(silent: bool) -> None:
        simulator.silence_all(math.inf if silent else 0)

    def fault(args: list[str]) -> None:
        name = args[0].lower()
        if name == "drive":
            axes = args[1:] or [YAW]
            for axis in axes:
                if axis not in simulator.axes:
                    raise ControlError(f"no axis {axis!r}; axes {', '.join(simulator.axes)}")
                simulator.set_axis_fault(axis, True)
        elif name == "case_sensor":
            simulator.set_case_sensor_fault(True)
        else:
            raise ControlError(f"unknown fault {name!r}; names: {', '.join(FAULT_NAMES)}")

    def node_silence(args: list[str]) -> None:
        node, switch = args[0], (args[1].lower() if len(args) > 1 else "on")
        duration = 0.0 if switch == "off" else math.inf if switch == "on" else float(switch)
        nodes = list(simulator.node_ids) if node == "all" else [node]
        for name in nodes:
            simulator.set_silent(name, duration)

    def gnss(args: list[str]) -> None:
        if len(args) < 4:
            raise ControlError("gnss LAT LON ALT_MSL HEADING [ACCURACY_M]")
        latitude, longitude, altitude, heading = (float(a) for a in args[:4])
        with simulator._lock:
            simulator.latitude_deg, simulator.longitude_deg = latitude, longitude
            simulator.altitude_m, simulator.heading_deg = altitude, heading % 360.0
            if len(args) > 4:
                simulator.position_accuracy_m = float(args[4])

    def inclination(args: list[str]) -> None:
        if len(args) != 2:
            raise ControlError("inclination ROLL PITCH (deg)")
        with simulator._lock:
            simulator.inclination_deg = (float(args[0]), float(args[1]))

    def eed(args: list[str]) -> None:
        if not args:
            raise ControlError("eed CODE [OPERATION] [LOCATION] [NODE]")
        code, operation, location = ([int(a, 0) for a in args[:3]] + [0, 0])[:3]
        simulator.emit_eed(code, operation, location,
                           node=args[3] if len(args) > 3 else "turret")

    control = SimControl(
        "canaero_turret_sim", simulator.state, links=[link] if link is not None else [],
        silence=silence,
        no_nack="CANaerospace services have no negative acknowledge the turret sends; its "
                "error path is the EED event (fault, eed)",
        fault=fault, fault_names=FAULT_NAMES, clear_device=simulator.clear_faults,
        axes=lambda: simulator.axes.values(),
        request_names=lambda: REQUESTS + tuple(simulator.command_names()),
        request_faults=simulator.request_faults)
    control.add_verb("node_silence", node_silence,
                     "node_silence NODE|all [on|off|SECONDS] "
                     "(NODE: turret, cover, rover_gnss, base_gnss, zoom)")
    control.add_verb("lose", lambda a: simulator.lose_frames(
        a[0], int(a[1]) if len(a) > 1 else 1), "lose KEY [COUNT] (e.g. yaw_position)")
    control.add_verb("repeat", lambda a: simulator.repeat_frames(
        a[0], int(a[1]) if len(a) > 1 else 1), "repeat KEY [COUNT]")
    control.add_verb("malformed", lambda a: simulator.send_malformed(int(a[0]) if a else 3),
                     "malformed [COUNT]")
    control.add_verb("eed", eed, "eed CODE [OPERATION] [LOCATION] [NODE]")
    control.add_verb("gnss", gnss, "gnss LAT LON ALT_MSL HEADING [ACCURACY_M]: base GNSS "
                     "position (deg, m above mean sea level) and rover heading (deg)")
    control.add_verb("inclination", inclination, "inclination ROLL PITCH: the base's "
                     "inclinometer (deg)")
    return control
