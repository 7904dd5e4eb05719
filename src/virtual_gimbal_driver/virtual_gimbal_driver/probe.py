"""The virtual gimbal's read-only probe for gimbal_probe: ``ID`` over TCP (no ROS)."""

from __future__ import annotations

from gimbal_driver_common.errors import GimbalError
from gimbal_driver_common.probe import (
    Attempt,
    Found,
    NoAnswer,
    ProbeLink,
    WatchedStream,
    line_verdict,
)

from .client import VirtualGimbalClient
from .protocol import parse_identity

#: the simulator's default port (config/virtual_gimbal_driver.yaml)
DEFAULT_PORT = 4950


def probe(link: ProbeLink) -> list[Attempt]:
    """One attempt on TCP: connect and send ``ID`` (a read; nothing else goes out)."""
    if link.kind != 'tcp':
        return []
    port = link.port or DEFAULT_PORT
    return [Attempt(f'line protocol ID on TCP port {port}', f'tcp {link.host}:{port}',
                    lambda: identify(link.host, port, link.timeout),
                    documented=port == DEFAULT_PORT)]


def identify(host: str, port: int, timeout: float) -> Found:
    client = VirtualGimbalClient(host, port, timeout=timeout)
    client.stream = watched = WatchedStream(client.stream)
    try:
        client.open()
        identity = parse_identity(client.request('ID'))
    except GimbalError as exc:
        raise NoAnswer(line_verdict([watched], 'virtual gimbal', exc)) from None
    finally:
        client.close()
    return Found(
        device=f'virtual gimbal {identity.model}', protocol='virtual gimbal line protocol (TCP)',
        link={'host': host, 'port': port},
        identity={'model': identity.model, 'serial': identity.serial_number,
                  'firmware': identity.firmware_version},
        parameters={'host': host, 'port': port})
