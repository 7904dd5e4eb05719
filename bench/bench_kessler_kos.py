"""Benchmark of kessler_kos_driver: kOS codec, node against the in-process kOS simulator (TCP).

The node polls GetMotorInfo every ``poll_period`` (default 1/publish_rate) and receives
MotorPosition / PlaybackStatus notifications; it publishes joint_states as each report
arrives (at most ``publish_rate``) with the time the report was read as ``header.stamp``.
"""

from __future__ import annotations

import math

from command_stream import DeviceRecorder, StreamSpec
from driver_bench import (
    check_targets,
    codec_figures,
    explain_latency,
    explain_streamed_rate,
    node_figures,
)
from driver_bench import tcp_wire_limit_frames_per_s as tcp_limit

from kessler_kos_driver.protocol import FrameParser, MotorInfo, MotorInfoEntry, decode
from kessler_kos_driver.sim import KosSimulator, SimSettings

PACKAGE = 'kessler_kos_driver'
DEFAULT_PUBLISH_RATE = 50.0   # the node's declared default (GimbalDriverNode)
PAN_ADDRESS = 2
TWO_PI = 2.0 * math.pi


def codec() -> dict:
    """MotorInfo response for one motor: what the device sends per motor for every poll."""
    entry = MotorInfoEntry(PAN_ADDRESS, 12.345, 0.0, 100.0, 5.0, 5.0, 10.0)
    message = MotorInfo([entry], more_follows=True)
    frame = message.encode()
    parser = FrameParser()

    def receive() -> object:
        return [decode(f) for f in parser.feed(frame)]   # the client's path: split + decode

    return codec_figures(
        'MotorInfo response, 1 motor (polled state)', len(frame), message.encode, receive,
        'Ethernet 100 Mbit/s, one frame per TCP segment', tcp_limit(len(frame)))


def run(domain: int) -> dict:
    results: dict = {'transport': 'tcp loopback; GetMotorInfo polled at publish_rate',
                     'codec': codec()}
    sim = KosSimulator(SimSettings(precalibrated=True), port=0, discovery_port=0)
    pan = sim.device.motors[PAN_ADDRESS]
    recorder = DeviceRecorder(sim.server, {'received': lambda: pan.target})
    sim.start()
    # rad on joint 'pan' (scale 2*pi rad per rotation), inside the calibrated 0..100 rot
    stream = StreamSpec('pan', 20.0, lambda rad: rad / TWO_PI, 2e-5, move_targets=(10.0, 40.0),
                        node_name=PACKAGE)

    try:
        results.update(node_figures(domain, PACKAGE, {
            'host': '127.0.0.1', 'port': sim.port, 'publish_rate': DEFAULT_PUBLISH_RATE,
            'reconnect_period': 0.5,
        }, stream, recorder))
    finally:
        sim.stop()
    explain_latency(results, (
        'The node publishes each MotorInfo reply or MotorPosition/PlaybackStatus '
        'notification as it arrives (stamp = when the client read it), so the figure is '
        'publish + DDS transfer.'))
    explain_streamed_rate(results, (
        'the GetMotorInfo polls, one every poll_period (default 1/publish_rate); a motor '
        'that stops also sends MotorPosition'))
    check_targets(results)
    return results
