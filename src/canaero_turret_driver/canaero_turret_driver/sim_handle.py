"""The turret simulator behind an slcan pty in the caller's process: its faults (soak) and
its receive side (the cross-driver process tests)."""

from __future__ import annotations

import math
import random
import time
from pathlib import Path
from typing import Any

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_control import SimControl
from gimbal_driver_common.sim_handle import LibraryWarning, SimHandle


class CanaeroSimHandle(SimHandle):
    """The receive side logs the turret's CANaerospace command messages (every one acts:
    set-points, stops, modes, controls) and node-service requests; identification (IDS) and
    data upload (DUS, a read of node memory) only read."""

    not_applicable = {'nack': 'CANaerospace services have no negative acknowledge the turret '
                              'sends; its error path is the EED event, injected as fault_bits'}
    far_move = ('yaw', 2.5, 0.2)
    takeover_goal = {'yaw': 0.2, 'pitch': 0.1}
    stop_requests = ('stop_actuators',)
    stop_request = 'stop_actuators'
    # preset 0 is the turret's remembered position, recalled (and cleared) as it is
    valid_preset_calls = (('clear_preset', 0), ('goto_preset', 0))
    # node_timeout: the silence that counts as a lost link. The simulator broadcasts from a
    # thread of the test process, which the parallel suite can stall for more than 0.6 s:
    # then the node rightly reported the turret silent in the middle of a move
    # (test_crash_safety, "turret node 1 silent for 0.6 s (4 other CAN frames arrived
    # meanwhile ...)"), as test_device.py saw before. 2 s is longer than that stall and
    # still quick; the link-loss tests wait for the loss either way. actuator_mode stays
    # 'auto_brake' (the registration's): the node sends it only to an axis that does not
    # report it, so a takeover keeps the move
    process_test_parameters = {'transmission_intervals': None,
                               'node_timeout': 2.0, 'stale_timeout': 0.6}
    #: the turret's set-points have no speed field (it moves at its own profile): a slow yaw
    #: drive (11.5 deg/s = 0.2 rad/s) makes the far move last
    SLOW_YAW_DEG_S = 11.5
    MOTION_SUFFIXES = ('_position_setpoint', '_velocity_setpoint', '_relative_setpoint',
                       '_actuator_mode')
    MOTION_KEYS = ('stop_actuators', 'restore_position')
    READ_SERVICES = ('service IDS', 'service DUS')

    def __init__(self, spec: DriverSpec, workdir: Path, process_tests: bool = False) -> None:
        super().__init__(spec, workdir, process_tests)
        self.simulator: Any = None   # the simulator, once start() made it
        self._controls: SimControl | None = None

    def start(self) -> None:
        from canaero_turret_driver.sim import (
            SimConfig,
            SlcanSession,
            TurretSimulator,
            make_control,
        )
        from gimbal_driver_common.sim_server import PtySimServer

        config = SimConfig(yaw_max_velocity=self.SLOW_YAW_DEG_S) if self.process_tests \
            else SimConfig()
        simulator: Any = TurretSimulator(config)   # its handle is wrapped below
        self.simulator = simulator
        simulator.handle = self._recording(simulator)
        server = PtySimServer(lambda: SlcanSession(simulator), link_path=self.link).start()
        # its silence verb quiets the CAN nodes; the slcan adapter keeps answering
        self._controls = make_control(simulator, server)
        self._started(server, server)

    def controls(self) -> SimControl:
        if self._controls is None:
            raise RuntimeError(f'{self.spec.name}: the simulator is not started')
        return self._controls

    def axis_limits(self, joint: str) -> tuple[float, float]:
        axis = self.simulator.axes[joint]  # degrees; set-points carry no speed
        return math.radians(axis.move_speed), math.radians(axis.acceleration)

    def _recording(self, simulator):
        """The simulator's frame handler, logging the commands and service requests."""
        from canaero_turret_driver.protocol import nodeservice
        from canaero_turret_driver.protocol.message import CanAerospaceMessage

        handle = simulator.handle

        def recorded(frame):
            commands = len(simulator.received_commands)
            replies = handle(frame)
            for key, value in simulator.received_commands[commands:]:
                self.record(f'{key} {value}')
            service = nodeservice.service_channel_of(frame.arbitration_id)
            if service is not None and service[1]:  # a request
                try:
                    code = CanAerospaceMessage.from_frame(frame.arbitration_id,
                                                          frame.data).service_code
                    self.record(f'service {nodeservice.ServiceCode(code).name}')
                except ValueError:
                    self.record(f'service {frame.data.hex()}')
            return replies

        return recorded

    def set_gnss(self, latitude: float, longitude: float, altitude_msl: float,
                 heading: float, roll: float = 0.0, pitch: float = 0.0) -> None:
        """The base GNSS position (deg, m above mean sea level), the rover heading (deg,
        clockwise from north) and the inclinometer (deg), through the control verbs."""
        self.control(f'gnss {latitude!r} {longitude!r} {altitude_msl!r} {heading!r}')
        self.control(f'inclination {roll!r} {pitch!r}')

    def changing(self, request: str) -> bool:
        return request not in self.READ_SERVICES

    def motion(self, request: str) -> bool:
        key = request.split()[0]
        return key.endswith(self.MOTION_SUFFIXES) or key in self.MOTION_KEYS

    def moving(self, joint: str) -> bool:
        return self.simulator.state()['axes'][joint]['velocity'] != 0.0

    def lost_frames(self, rng: random.Random) -> None:
        self.simulator.lose_frames(rng.choice(('yaw_position', 'pitch_position')),
                                   rng.randrange(1, 6))

    def malformed_frames(self, rng: random.Random) -> None:
        self.simulator.send_malformed(rng.randrange(1, 5))

    def fault_bits(self, rng: random.Random) -> None:
        axis = rng.choice(tuple(self.simulator.axes))
        self.simulator.set_axis_fault(axis, True)
        time.sleep(0.5)
        self.simulator.set_axis_fault(axis, False)  # the cause goes away; reset_faults follows

    def provoke_library_warning(self) -> LibraryWarning:
        # an emergency event: the client decodes it and warns (canaero_turret_driver.client)
        self.control('eed 0x0042 1 2')
        return LibraryWarning('canaero_turret_driver.client', 'error 0x0042 operation 1')
