"""The conformance suite against capture_driver_node and capture_sim (TCP), as processes."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_common.ros.conformance_testing import DriverConformance, SimulatorHandle
from gimbal_driver_common.testing import ManagedProcess, free_tcp_port

PKG = 'capture_driver'
AXIS_IDS = {'pan': '1', 'tilt': '2'}
# Device commands that set an axis in motion (the simulator counts requests by command).
MOTION_COMMANDS = ('MOT_SendPosition', 'MOT_Update', 'MOT_SetSpeed', 'PRST_GoToPreset',
                   'SCN_StartScanZigZag', 'SCN_StartScanSnake', 'DG_GoToCamera',
                   'MOT_Home')


class CaptureSim(SimulatorHandle):
    """capture_sim as a process; its control port reports the device state and request
    counts per command (the receive side) and drops the link."""

    def __init__(self, domain: int) -> None:
        self.port, self.control_port = free_tcp_port(), free_tcp_port()
        self.process = ManagedProcess.ros(PKG, 'capture_sim', domain, [
            '--port', str(self.port), '--control-port', str(self.control_port),
            '--time-scale', '4'])
        self.process.wait_for_output('{"ready": "capture_sim"', timeout=30)

    def control(self, line: str) -> str:
        with socket.create_connection(('127.0.0.1', self.control_port), timeout=5.0) as sock:
            stream = sock.makefile('rw')
            stream.write(line + '\n')
            stream.flush()
            return stream.readline().strip()

    def state(self) -> dict:
        answer = self.control('state')
        assert answer.startswith('ok '), answer
        return json.loads(answer[3:])

    def link_parameters(self) -> list[str]:
        return ['host:=127.0.0.1', f'port:={self.port}']

    def motion_received(self) -> object:
        counts = self.state()['requests_by_command']
        return {name: counts.get(name, 0) for name in MOTION_COMMANDS}

    def moving(self, joint: str) -> bool:
        state = self.state()
        return state['axes'][AXIS_IDS[joint]]['velocity'] != 0.0 or state['scanning']

    def drop_link(self, seconds: float) -> None:
        assert self.control(f'drop {seconds}') == 'ok'

    def close(self) -> None:
        self.process.stop()


class TestCaptureConformance(DriverConformance):
    __test__ = True
    package = PKG
    node_executable = 'capture_driver_node'
    node_name = 'capture_driver'
    joints = ('pan', 'tilt')
    small_move = {'pan': 0.4, 'tilt': -0.2}
    far_move = ('pan', -2.5, 0.1)
    jog = ('pan', 0.3)
    tolerance = 2e-3
    preset_index = 2
    scan = dict(pattern='snake', pan_min=-0.2, pan_max=0.2, tilt_min=0.0, tilt_max=0.2,
                speed=0.5, tilt_step=0.1)

    def start_simulator(self, workdir: Path, domain: int) -> SimulatorHandle:
        return CaptureSim(domain)
