"""The Kessler kOS device's read-only probe for gimbal_probe (no ROS).

What goes out: the document's initialisation sequence, which is the session handshake:
GetDeviceInfo, then (only when the password matches) UserPassword, GetMotorInfo and
GetDeviceGuid, and the client's keep-alive poll (GetMotorInfo) while it is open. The device
reports its password in DeviceInfo; the client compares it locally, so a wrong or missing
password is never sent. Neither the given password nor the device's is ever printed.
"""

from __future__ import annotations

from gimbal_driver_common.probe import (
    Attempt,
    Found,
    NoAnswer,
    ProbeLink,
    WatchedStream,
    line_verdict,
)
from gimbal_driver_common.transport import TcpStream

from .client import KosClient, KosError, PasswordRejected
from .device import DEVICE_MODELS
from .protocol import DEFAULT_TCP_PORT

#: the node's default joints (config/kessler_kos_driver.yaml): slider, pan, tilt
DEFAULT_MOTORS = [1, 2, 3]


def probe(link: ProbeLink) -> list[Attempt]:
    if link.kind != 'tcp':
        return []
    port = link.port or DEFAULT_TCP_PORT
    return [Attempt(f'kOS GetDeviceInfo handshake on TCP port {port}', f'tcp {link.host}:{port}',
                    lambda: identify(link.host, port, link.password, link.timeout),
                    documented=port == DEFAULT_TCP_PORT)]


def identify(host: str, port: int, password: str, timeout: float) -> Found:
    watched: list[WatchedStream] = []

    def factory(h: str, p: int) -> WatchedStream:
        watched.append(WatchedStream(TcpStream(h, p, connect_timeout=timeout)))
        return watched[-1]

    client = KosClient(host, port, password=password, connect_timeout=timeout,
                       reply_timeout=max(timeout / 3.0, 0.1), stream_factory=factory)
    notes: list[str] = []
    try:
        client.connect()
    except PasswordRejected:
        if client.device_info is None:
            raise NoAnswer('the device refused the password') from None
        notes.append('the given --password does not match the device password (it was not '
                     'sent)' if password else
                     'a password is needed: probe again with --password to read the motors, '
                     'and give the driver a password_file')
    except KosError as exc:
        raise NoAnswer(line_verdict(watched, 'kOS', exc)) from None
    finally:
        client.close()
    info = client.device_info
    assert info is not None
    motors = sorted(client.motors)
    identity = {'model': DEVICE_MODELS.get(info.device_type, f'kOS device type {info.device_type}'),
                'firmware': info.firmware}
    if client.guid:
        identity['GUID'] = client.guid
    ids: dict[str, int | list[int]] = {'device address': info.device_addr,
                                       'network id': info.network_id}
    parameters: dict = {'host': host, 'port': port}
    if motors:
        ids['motor addresses'] = motors
        if motors == DEFAULT_MOTORS:
            parameters['motor_addresses'] = motors
        else:
            notes.append(f'motors at addresses {motors}: set joint_names and motor_addresses '
                         '(and the per-joint lists) to match')
    if password or (notes and 'password is needed' in notes[0]):
        parameters['password_file'] = ''
        notes.append('set password_file to a file (mode 0600) holding the password')
    return Found(device=identity['model'], protocol='kOS network protocol (TCP)',
                 link={'host': host, 'port': port}, identity=identity, ids=ids,
                 parameters=parameters, notes=notes)
