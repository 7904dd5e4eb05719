"""The U-Camera's read-only probe for gimbal_probe (no ROS).

What goes out: Request Gimbal Version and Request Telemetry Rate (manual: device-info
requests, answered with a report; nothing changes). The client's I/O thread re-sends a mode
and angles only after a mode was commanded, and the probe commands none. The gimbal type
comes from the telemetry it streams by itself.
"""

from __future__ import annotations

import time
from functools import partial

from gimbal_driver_common.probe import (
    Attempt,
    Found,
    NoAnswer,
    ProbeLink,
    WatchedStream,
    line_verdict,
)
from gimbal_driver_common.transport import SerialStream

from .client import UCameraClient, UCameraError
from .protocol import GimbalType

#: manual: "UCSP is a standard serial protocol at 115200 bps, 1 stop bit and no parity"
BAUD_RATES = (115200,)


def probe(link: ProbeLink) -> list[Attempt]:
    if link.kind != 'serial':
        return []
    return [Attempt(f'UCSP Request Gimbal Version at {baud} baud 8N1',
                    f'serial {link.serial_port}',
                    partial(identify, link.serial_port, baud, link.timeout))
            for baud in BAUD_RATES]


def identify(port: str, baudrate: int, timeout: float) -> Found:
    watched: list[WatchedStream] = []

    def factory() -> WatchedStream:
        watched.append(WatchedStream(SerialStream(port, baudrate)))
        return watched[-1]

    client = UCameraClient(stream_factory=factory, request_timeout=max(timeout / 4.0, 0.1),
                           silence_timeout=max(timeout, 0.5))
    try:
        version = client.start(timeout=timeout)
    except UCameraError as exc:
        raise NoAnswer(line_verdict(watched, 'UCSP', exc)) from None
    try:
        deadline = time.monotonic() + timeout / 2.0
        while client.state().gimbal_type is None and time.monotonic() < deadline:
            time.sleep(0.02)
        gimbal_type = client.state().gimbal_type
        try:
            rate: int | None = client.request_telemetry_rate(max(timeout / 4.0, 0.1))
        except UCameraError:
            rate = None
    finally:
        client.stop()
    kind = GimbalType(gimbal_type).name.lower() if gimbal_type in set(GimbalType) else 'unknown'
    identity = {'model': f'U-Camera ({kind} gimbal)', 'serial': version.serial_number,
                'firmware': version.firmware}
    parameters = {'serial_port': port, 'baudrate': baudrate}
    notes = []
    if rate is not None:
        identity['telemetry rate'] = f'{rate} Hz'
    else:
        notes.append('the telemetry rate was not reported')
    return Found(device='Airelectronics U-Camera', protocol='UCSP over serial (8N1)',
                 link={'serial_port': port, 'baudrate': baudrate}, identity=identity,
                 parameters=parameters, notes=notes)
