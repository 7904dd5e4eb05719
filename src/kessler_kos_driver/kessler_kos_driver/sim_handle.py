"""The kOS simulator in the caller's process: its faults (soak) and its receive side (the
cross-driver process tests)."""

from __future__ import annotations

import random
import time
from pathlib import Path
from typing import Any

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_control import SimControl
from gimbal_driver_common.sim_handle import LibraryWarning, SimHandle

from .registration import SIM_RIG


class KesslerSimHandle(SimHandle):
    """The receive side logs kOS message types; Get* requests and the password handshake
    only read, every Action (moves, stops, playback, resets) is motion."""

    not_applicable = {'nack': 'kOS answers a bad request with ErrorStatus, injected as '
                              'fault_bits (device error broadcast)'}
    #: SI on the example rig (registration.SIM_RIG): from pan -pi toward +3 rad at 0.05 rad/s
    #: (0.8 rotations/s) lasts about a minute of simulated time
    far_move = ('pan', 3.0, 0.05)
    takeover_goal = {'pan': 0.3, 'tilt': 0.2}
    stop_requests = ('SetPositionSpeedAcceleration', 'StopPlayback')
    stop_request = 'SetPositionSpeedAcceleration'  # speed 0 at the current position
    READS = ('UserPassword', 'DevicePassword')
    #: the simulator's time scale with ``process_tests`` (their moves settle sooner)
    PROCESS_TESTS_TIME_SCALE = 2.0

    def __init__(self, spec: DriverSpec, workdir: Path, process_tests: bool = False) -> None:
        super().__init__(spec, workdir, process_tests)
        self.sim: Any = None   # the simulator, once start() made it
        self.actions: set[str] = set()

    def start(self) -> None:
        from kessler_kos_driver.protocol import messages
        from kessler_kos_driver.sim import KosSimulator, SimSettings

        self.actions = {name for name, value in vars(messages).items()
                        if isinstance(value, type) and issubclass(value, messages.Action)}
        time_scale = self.PROCESS_TESTS_TIME_SCALE if self.process_tests else 1.0
        self.sim = KosSimulator(SimSettings(password=self.spec.password, precalibrated=True,
                                            time_scale=time_scale),
                                port=self.port, discovery_port=0)
        handle = self.sim.device.handle

        def recorded(message, frame, session):
            self.record(type(message).__name__)
            return handle(message, frame, session)

        self.sim.device.handle = recorded
        self.sim.start()
        self.port = self.sim.port
        self._started(self.sim.server, self.sim)

    def controls(self) -> SimControl:
        return self.sim.controls

    def changing(self, request: str) -> bool:
        return not (request.startswith('Get') or request in self.READS)

    def motion(self, request: str) -> bool:
        return request in self.actions

    def moving(self, joint: str) -> bool:
        device = self.sim.device
        with device.lock:
            motor = next(m for m in device.motors.values() if m.role == joint)
            return motor.moving or abs(motor.velocity) > 1e-9

    def device_target(self, joint: str) -> float | None:
        """The motor's target (rotations) in SI on the example rig: offset + rotations *
        span / end (registration.SIM_RIG, the spec's calibrated_spans/joint_offsets)."""
        addresses = dict(zip(self.spec.joints, self.spec.node_parameters['motor_addresses'],
                             strict=True))
        motor = self.sim.device.motors[addresses[joint]]
        target = motor.target  # None: no move since rest
        if target is None or not motor.end:
            return None
        rig = SIM_RIG[joint]
        return rig.offset + target * rig.span / motor.end

    def axis_limits(self, joint: str) -> tuple[float, float]:
        """Motor rotations in SI on the example rig: |span / end| per rotation
        (registration.SIM_RIG, as :meth:`device_target`)."""
        device = self.sim.device
        with device.lock:
            motor = next(m for m in device.motors.values() if m.role == joint)
            scale = abs(SIM_RIG[joint].span / motor.end) if motor.end else 0.0
            return motor.move_speed * scale, motor.acceleration * scale

    def malformed_frames(self, rng: random.Random) -> None:
        from kessler_kos_driver.protocol import MotorInfo, MotorInfoEntry

        frame = bytearray(MotorInfo([MotorInfoEntry(2, 1.0, 0.0, 100.0, 5.0, 5.0, 10.0)],
                                    more_follows=True).encode())
        frame[len(frame) // 2] ^= 0xFF
        self.server.inject(bytes(frame))

    def lost_frames(self, rng: random.Random) -> None:
        # replies lost for a moment, shorter than the driver's link watchdog
        self.server.set_silent(True)
        time.sleep(0.3)
        self.server.set_silent(False)

    def fault_bits(self, rng: random.Random) -> None:
        from kessler_kos_driver.protocol import ErrorStatus

        with self.sim.device.lock:
            self.sim.device.broadcast(ErrorStatus(16, 1))  # axis fault reported on the slider

    def provoke_library_warning(self) -> LibraryWarning:
        # bytes without the 0x04 version byte: skipped while resynchronising
        self.control(f'garbage hex {"ff" * 8}')
        return LibraryWarning('kessler_kos_driver.client', 'garbage bytes')
