"""The Capture pedestal's read-only probe for gimbal_probe (no ROS).

What goes out: the COM_Connect session handshake (spec 6.1: the controller sends COM_Connect
on a TCP connect, the host answers COM_Connect, the controller ACKs) and the four identity
getters COM_GetSn, COM_GetFw, COM_GetHw, COM_GetPn (no argument, a returned value: reads).
The client's ``identity()`` is not used: on a getter the device NACKs it clears the error
flag that NACK raised (ERR_ClearErrors, a write), which a probe must not send.
"""

from __future__ import annotations

from functools import partial

from gimbal_driver_common.probe import (
    Attempt,
    Found,
    NoAnswer,
    ProbeLink,
    WatchedStream,
    line_verdict,
)
from gimbal_driver_common.transport import SerialStream, TcpStream

from .client import CaptureClient
from .device_requests import IDENTITY_GETTERS
from .errors import CaptureError

#: spec 6.1, Table 4: the controller's TCP port
TCP_PORT = 4949
#: spec 6.2, Table 5: every serial line runs 115200 8N1 (the only rate documented)
BAUD_RATES = (115200,)
GROUP_ID = 0  # a single pedestal


def probe(link: ProbeLink) -> list[Attempt]:
    if link.kind == 'tcp':
        port = link.port or TCP_PORT
        return [Attempt(f'COM_Connect + identity getters on TCP port {port}',
                        f'tcp {link.host}:{port}',
                        lambda: identify_tcp(link.host, port, link.timeout),
                        documented=port == TCP_PORT)]
    if link.kind == 'serial':
        return [Attempt(f'COM_Connect + identity getters at {baud} baud 8N1',
                        f'serial {link.serial_port}',
                        partial(identify_serial, link.serial_port, baud, link.timeout))
                for baud in BAUD_RATES]
    return []


def identify_tcp(host: str, port: int, timeout: float) -> Found:
    found = identify(lambda: TcpStream(host, port, connect_timeout=timeout), True, timeout)
    found.link = {'transport': 'tcp', 'host': host, 'port': port}
    found.protocol = 'Capture binary protocol over TCP'
    found.parameters = {'transport': 'tcp', 'host': host, 'port': port, 'group_id': GROUP_ID}
    return found


def identify_serial(port: str, baudrate: int, timeout: float) -> Found:
    found = identify(lambda: SerialStream(port, baudrate), False, timeout)
    found.link = {'transport': 'serial', 'serial_port': port, 'baudrate': baudrate}
    found.protocol = 'Capture binary protocol over serial (8N1)'
    found.parameters = {'transport': 'serial', 'serial_port': port, 'baudrate': baudrate,
                        'group_id': GROUP_ID}
    return found


def identify(open_stream, expect_greeting: bool, timeout: float) -> Found:
    """Handshake, then the identity getters, each within a share of ``timeout``."""
    watched: list[WatchedStream] = []

    def factory() -> WatchedStream:
        watched.append(WatchedStream(open_stream()))
        return watched[-1]

    share = round(max(timeout / 3.0, 0.1), 2)
    client = CaptureClient(factory, group=GROUP_ID, timeout=share, greeting_timeout=share,
                           expect_greeting=expect_greeting, batch_reads=False)
    try:
        client.connect()
    except CaptureError as exc:
        client.close()
        raise NoAnswer(line_verdict(watched, 'Capture', exc)) from None
    identity: dict[str, str] = {}
    unread: list[str] = []
    try:
        for attribute, getter in IDENTITY_GETTERS:
            try:
                value = client.request(getter)
            except CaptureError as exc:
                unread.append(f'{getter}: {exc}')
                continue
            identity[attribute.replace('_', ' ')] = f'{value:g}' if isinstance(value, float) \
                else str(value)
    finally:
        client.close()
    if not identity:
        # a byte 0x06 in another device's stream reads as the handshake's ACK: a Capture
        # controller answers its identity getters with data
        raise NoAnswer(f'no identity getter answered with data ({"; ".join(unread)}): not a '
                       'Capture controller')
    notes = [f'not read: {"; ".join(unread)}'] if unread else []
    return Found(device='Capture Systems pan-tilt pedestal', protocol='', link={},
                 identity=identity, ids={'group_id': GROUP_ID}, notes=notes)
