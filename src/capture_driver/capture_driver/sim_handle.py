"""The Capture simulator in the caller's process: its faults (soak) and its receive side
(the cross-driver process tests)."""

from __future__ import annotations

import math
import random
from pathlib import Path
from typing import Any

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_control import SimControl
from gimbal_driver_common.sim_handle import LibraryWarning, SimHandle, Takeover

#: commands that move or stop a Capture axis
MOTION_COMMANDS = ('MOT_SendPosition', 'MOT_Update', 'MOT_SetSpeed', 'MOT_SetSpeedMode',
                   'PRST_GoToPreset', 'PRST_StopPresetLooping', 'SCN_StartScanZigZag',
                   'SCN_StartScanSnake', 'SCN_StopScan', 'DG_GoToCamera', 'MOT_Home',
                   'GPS_StopTargetLooping')
AXIS_IDS = {'pan': 1, 'tilt': 2}


class CaptureSimHandle(SimHandle):
    """The receive side logs command names; a query (no argument, a returned value) and the
    COM_Connect handshake only read."""

    far_move = ('pan', 2.5, 0.1)
    takeover = Takeover.STOPS_ON_CONNECT
    stop_requests = ('MOT_SetSpeedMode', 'MOT_SetSpeed', 'MOT_Update', 'SCN_StopScan')
    stop_request = 'MOT_SetSpeed'  # speed 0: a jog's stop
    # clearing an empty slot is a no-op on the device
    valid_preset_calls = (('clear_preset', None),)
    process_test_parameters = {'status_period': 0.5}
    #: the device answers ACK to every opcode it does not know (a third-party controller)
    ack_unknown = False
    #: the only commands the device knows (table names or ``sim.KNOWN_SETS`` names);
    #: None: the whole table
    known_commands: tuple[str, ...] | None = None

    def __init__(self, spec: DriverSpec, workdir: Path, process_tests: bool = False) -> None:
        super().__init__(spec, workdir, process_tests)
        self.sim: Any = None   # the simulator, once start() made it

    def start(self) -> None:
        from capture_driver.protocol import BY_OPCODE
        from capture_driver.sim import CaptureSimulator, PedestalModel

        self.sim = CaptureSimulator(PedestalModel(
            known_commands=self.known_commands, ack_unknown=self.ack_unknown),
            tcp_port=self.port).start()
        handle = self.sim.model.handle

        def recorded(frame, session):
            known = BY_OPCODE.get(frame.opcode)
            self.record(known.name if known is not None else f'0x{frame.opcode:04X}',
                        f'axis {frame.axis}' if frame.axis else '')
            return handle(frame, session)

        self.sim.model.handle = recorded
        self.port = self.sim.tcp.port
        self._started(self.sim.tcp, self.sim)

    def set_gps(self, latitude: float, longitude: float, altitude: float,
                heading: float) -> None:
        """The GPS position (deg, deg, m) and heading (deg clockwise from north), with a fix."""
        self.control(f'gps {latitude!r} {longitude!r} {altitude!r} {heading!r}')

    def set_inserted(self, latitude: float | None, longitude: float = 0.0,
                     altitude: float = 0.0, heading: float = 0.0) -> None:
        """The user-inserted position and heading with the override flag (None: flag off)."""
        self.control('inserted off' if latitude is None else
                     f'inserted {latitude!r} {longitude!r} {altitude!r} {heading!r}')

    def changing(self, request: str) -> bool:
        from capture_driver.protocol import COMMANDS, DataType

        name = request.split()[0]  # a log may carry the axis after the name
        command = COMMANDS.get(name)
        reads = command is not None and command.arg is DataType.NONE \
            and command.ret is not DataType.NONE
        return not (name == 'COM_Connect' or reads)

    def motion(self, request: str) -> bool:
        return request.split()[0] in MOTION_COMMANDS

    def moving(self, joint: str) -> bool:
        model = self.sim.model
        with model.lock:
            return model.axes[AXIS_IDS[joint]].velocity != 0.0 or model.scan is not None

    def controls(self) -> SimControl:
        return self.sim.controls

    def axis_limits(self, joint: str) -> tuple[float, float]:
        model = self.sim.model
        with model.lock:  # load degrees; the profile the driver's MOT_Set* wrote
            axis = model.axes[AXIS_IDS[joint]]
            return math.radians(axis.move_speed), math.radians(axis.acceleration)

    def lost_frames(self, rng: random.Random) -> None:
        self.sim.model.lose_replies(rng.randrange(1, 4))

    def malformed_frames(self, rng: random.Random) -> None:
        from capture_driver.protocol import COMMANDS, DataType, Frame, encode_value

        opcode = COMMANDS['MOT_GetLoadPosition'].opcode
        frame = bytearray(Frame(0, 1, opcode, encode_value(DataType.F32, 12.5)).encode())
        frame[-1] ^= 0x5A  # checksum no longer matches
        self.server.inject(bytes(frame))

    def nack(self, rng: random.Random) -> None:
        self.sim.model.nack_next(count=rng.randrange(1, 4))

    def fault_bits(self, rng: random.Random) -> None:
        self.sim.model.inject_fault(rng.choice((1, 2)), 'over_current')

    def provoke_library_warning(self) -> LibraryWarning:
        # the client finds the connection closed under it (capture_driver.client)
        self.drop_link(0.5)
        return LibraryWarning('capture_driver.client', 'link lost')
