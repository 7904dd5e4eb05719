"""Benchmark of kessler_kos_driver: kOS codec, node against the in-process kOS simulator (TCP).

The node polls GetMotorInfo every ``poll_period`` (default 1/publish_rate) and receives
MotorPosition / PlaybackStatus notifications; it publishes joint_states as each report
arrives (at most ``publish_rate``) with the time the report was read as ``header.stamp``.
"""

from __future__ import annotations

from driver_bench import (
    check_targets,
    codec_figures,
    explain_latency,
    explain_streamed_rate,
    generic_run,
)
from driver_bench import tcp_wire_limit_frames_per_s as tcp_limit

from gimbal_driver_common.registry import driver
from kessler_kos_driver.protocol import FrameParser, MotorInfo, MotorInfoEntry, decode

PAN_ADDRESS = 2


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
    """The generic benchmark against the registered kOS simulator, plus the codec."""
    results = generic_run(driver('kessler_kos'), domain)
    results['transport'] = 'tcp loopback; GetMotorInfo polled at publish_rate'
    results['codec'] = codec()
    explain_latency(results, (
        'The node publishes each MotorInfo reply or MotorPosition/PlaybackStatus '
        'notification as it arrives (stamp = when the client read it), so the figure is '
        'publish + DDS transfer.'))
    explain_streamed_rate(results, (
        'the GetMotorInfo polls, one every poll_period (default 1/publish_rate); a motor '
        'that stops also sends MotorPosition'))
    check_targets(results)
    return results
