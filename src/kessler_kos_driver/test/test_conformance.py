"""The conformance suite against kessler_kos_driver_node (a process) and the kOS simulator
over TCP (in the test process, so the suite sees every message the device received)."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_common.ros.conformance_testing import DriverConformance, SimulatorHandle
from kessler_kos_driver.sim import KosSimulator, SimSettings

PASSWORD = 'Zq8-kos-secret'
# kOS messages that set a motor in motion (the rest read, configure or stop).
MOTION_MESSAGES = ('SetPositionSpeedAcceleration', 'BumpPositionSpeedAcceleration',
                   'SetupPlayback', 'StartPlayback', 'RapidToFirstKeyFrame')


class InProcessKos(SimulatorHandle):
    """KosSimulator on 127.0.0.1 (no discovery beacon) with its message handler wrapped to
    record the type of every message the device received."""

    def __init__(self) -> None:
        self.sim = KosSimulator(SimSettings(password=PASSWORD, precalibrated=True,
                                            time_scale=2.0), port=0, discovery_port=0)
        self.received: list[str] = []
        handle = self.sim.device.handle

        def recording_handle(message, frame, session):
            self.received.append(type(message).__name__)
            return handle(message, frame, session)

        self.sim.device.handle = recording_handle
        self.sim.start()

    def link_parameters(self) -> list[str]:
        return ['host:=127.0.0.1', f'port:={self.sim.port}', f'password:={PASSWORD}']

    def motion_received(self) -> object:
        return [name for name in list(self.received) if name in MOTION_MESSAGES]

    def moving(self, joint: str) -> bool:
        device = self.sim.device
        with device.lock:
            motor = next(m for m in device.motors.values() if m.role == joint)
            return motor.moving or abs(motor.velocity) > 1e-9

    def drop_link(self, seconds: float) -> None:
        self.sim.server.drop_link(seconds)

    def close(self) -> None:
        self.sim.stop()


class TestKesslerKosConformance(DriverConformance):
    __test__ = True
    package = 'kessler_kos_driver'
    node_executable = 'kessler_kos_driver_node'
    node_name = 'kessler_kos_driver'
    # rad (slider: joint_scales 2*pi per rotation), inside the simulator's calibrated
    # ranges: slider 0..200 rot, pan 0..100 rot, tilt 0..-40 rot
    joints = ('slider', 'pan', 'tilt')
    small_move = {'pan': 20.0, 'tilt': -20.0}
    far_move = ('pan', 600.0, 5.0)
    jog = ('pan', 20.0)
    tolerance = 0.011
    preset_index = 4
    scan = dict(pattern='sector', pan_min=10.0, pan_max=30.0, speed=10.0)

    def start_simulator(self, workdir: Path, domain: int) -> SimulatorHandle:
        return InProcessKos()
