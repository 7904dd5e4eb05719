"""Benchmark of canaero_turret_driver: CANaerospace codec, node against the in-process turret
simulator behind an slcan adapter on a pty.

The turret broadcasts its data identifiers periodically (100 ms by default, like the real
turret; at connect the node asks by TIS for yaw/pitch position and velocity every
1/publish_rate = 20 ms); the client stamps each frame on arrival and the node publishes the
positions as they arrive (at most ``publish_rate``). The node reads the pty with the
driver's chunked slcan reader (``canaero_turret_driver.slcan``); ``slcan_reception``
compares it with python-can's own slcan interface on the same traffic.
"""

from __future__ import annotations

import math
import tempfile
import threading
import time
from pathlib import Path

import can
from command_stream import DeviceRecorder, StreamSpec
from driver_bench import (
    add_note,
    check_targets,
    codec_figures,
    explain_latency,
    node_figures,
)
from harness import can_frame_bits, wire_limit_frames_per_s

from canaero_turret_driver.protocol import CanAerospaceMessage, DataType
from canaero_turret_driver.sim import (
    DEFAULT_INTERVALS_MS,
    PITCH,
    SimConfig,
    SlcanSession,
    TurretSimulator,
)
from canaero_turret_driver.slcan import open_bus
from gimbal_driver_common.sim_server import PtySimServer

PACKAGE = 'canaero_turret_driver'
DEFAULT_PUBLISH_RATE = 50.0   # the node's declared default (GimbalDriverNode)
YAW_POSITION_ID = 1303        # ICD data identifier "yaw_position" (FLOAT, deg)
TURRET_NODE = 1
CAN_BPS = 1_000_000
# what the node asks for by TIS at connect at its default publish_rate (request_intervals)
NODE_INTERVALS_MS = {**DEFAULT_INTERVALS_MS, 'yaw_position': 20, 'pitch_position': 20,
                     'yaw_velocity': 20, 'pitch_velocity': 20}


def codec() -> dict:
    """yaw_position broadcast: a FLOAT CANaerospace message in one CAN 2.0A frame."""
    message = CanAerospaceMessage.build(YAW_POSITION_ID, TURRET_NODE, DataType.FLOAT, 12.5,
                                        0, 7)
    data = message.to_bytes()

    def encode() -> bytes:   # the device side: build from a value, then the frame bytes
        return CanAerospaceMessage.build(YAW_POSITION_ID, TURRET_NODE, DataType.FLOAT, 12.5,
                                         0, 7).to_bytes()

    def decode() -> object:  # the client's path: parse the frame, decode the value
        return CanAerospaceMessage.from_frame(YAW_POSITION_ID, data).value

    bits = can_frame_bits(len(data))
    return codec_figures(
        f'yaw_position FLOAT message ({len(data)} data bytes, one CAN 2.0A frame)', len(data),
        encode, decode, f'CAN 1 Mbit/s, worst-case stuffed frame {bits} bits',
        wire_limit_frames_per_s(0, CAN_BPS, overhead_bits=bits))


class BroadcastCounter:
    """Counts the frames the simulator broadcasts (wraps ``TurretSimulator.poll``)."""

    def __init__(self, simulator: TurretSimulator) -> None:
        self._lock = threading.Lock()
        self.stamps: list[float] = []
        poll = simulator.poll

        def counted(now: float | None = None) -> list:
            frames = poll(now)
            if frames:
                with self._lock:
                    self.stamps.extend([time.monotonic()] * len(frames))
            return frames

        simulator.poll = counted

    def figures(self, start: float, end: float) -> dict:
        with self._lock:
            count = sum(1 for t in self.stamps if start <= t <= end)
            self.stamps.clear()
        return {'device_frames_per_s': round(count / max(end - start, 1e-9), 1)}


def slcan_reception_cost(chunked: bool, seconds: float = 2.0) -> dict:
    """CPU per received frame of an slcan reader on a pty (the driver's chunked one, or
    python-can's byte-by-byte one), fed by a simulator with the node's intervals."""
    with tempfile.TemporaryDirectory(prefix='bench-slcan-') as tmp:
        simulator = TurretSimulator(SimConfig(intervals_ms=dict(NODE_INTERVALS_MS)))
        server = PtySimServer(lambda: SlcanSession(simulator),
                              link_path=str(Path(tmp, 'tty'))).start()
        if chunked:
            bus = open_bus('slcan', server.port_name, sleep_after_open=0)
        else:
            bus = can.Bus(interface='slcan', channel=server.port_name, sleep_after_open=0)
        try:
            frames = 0
            cpu_start, start = time.thread_time(), time.monotonic()
            while time.monotonic() - start < seconds:
                if bus.recv(timeout=0.05) is not None:
                    frames += 1
            cpu = time.thread_time() - cpu_start
            wall = time.monotonic() - start
        finally:
            bus.shutdown()
            server.stop()
    return {'frames_per_s': round(frames / wall, 1),
            'cpu_us_per_frame': round(cpu / max(frames, 1) * 1e6, 1),
            'cpu_percent': round(100.0 * cpu / wall, 1)}


def run(domain: int) -> dict:
    results: dict = {'transport': 'slcan on a pty (no CAN bit timing), broadcasts every 20 ms',
                     'codec': codec()}
    tmp = tempfile.TemporaryDirectory(prefix='bench-canaero-')
    simulator = TurretSimulator(SimConfig())
    broadcasts = BroadcastCounter(simulator)
    server = PtySimServer(lambda: SlcanSession(simulator), link_path=str(Path(tmp.name, 'tty')))
    pitch = simulator.axes[PITCH]
    # one frame carries the whole command: the drive holds the target once it is handled
    recorder = DeviceRecorder(server, {
        'received': lambda: pitch.target})
    server.start()
    # joint 'pitch' in rad, pitch_direction +1, the drive in degrees (FLOAT)
    stream = StreamSpec('pitch', -0.25, math.degrees, 0.01, node_name=PACKAGE)

    try:
        results.update(node_figures(domain, PACKAGE, {
            'can_channel': server.port_name,
            'presets_file': str(Path(tmp.name, 'presets.yaml')),
            'publish_rate': DEFAULT_PUBLISH_RATE,
        }, stream, recorder, observe=broadcasts.figures))
    finally:
        server.stop()
        tmp.cleanup()
    results['slcan_reception'] = slcan_reception_cost(chunked=True)
    results['slcan_reception_python_can'] = slcan_reception_cost(chunked=False)
    explain_latency(results, (
        'Yaw and pitch positions are two frames of the same 20 ms cycle; the node publishes '
        'once both are in, so the yaw sample waits for the pitch frame behind it (one slcan '
        'record on the pty), and the pty adds the simulator\'s 5 ms poll tick.'))
    cpu, reception = results.get('cpu_percent', 0.0), results['slcan_reception']
    if cpu >= 10.0:
        add_note(results, (
            f'node CPU {cpu} % over 10 %: the turret broadcasts about '
            f'{results.get("device_frames_per_s", "?")} frames/s (every data identifier of the '
            'ICD, positions and velocities at 20 ms); the chunked slcan reader costs '
            f'{reception["cpu_us_per_frame"]} us of CPU per frame, '
            f'{reception["cpu_percent"]} % of a core at {reception["frames_per_s"]} frames/s '
            'in this run. The rest is the rclpy floor (the bare reference publisher of this '
            'run) and the driver code (decode, sequence check, cache).'))
    check_targets(results)
    return results
