"""The CANaerospace turret's read-only probe for gimbal_probe (no ROS).

First it only listens: the turret broadcasts its normal-operation data (positions,
velocities, status) by itself, and the node id in each frame's header is the turret's.
Then it asks that node (the ICD's default node 1 if the bus stayed silent) the
Identification Service (IDS, ICD 5.1: the "sign-of-life" service every CANaerospace unit
answers on service channel 0, a read). Nothing else goes out: no TIS, no set-point, no
NIS/FPS.
"""

from __future__ import annotations

import time

import can

from gimbal_driver_common.probe import Attempt, Found, NoAnswer, ProbeLink

from .client import ClientConfig, TurretClient, TurretError
from .protocol.errors import CodecError
from .protocol.identifiers import TURRET_NODE_ID, Direction, identifier_table
from .protocol.message import CanAerospaceMessage
from .slcan import open_bus

#: python-can waits 2 s after opening an slcan port by default (for boards that reset on
#: open); the probe's time limit has no room for it
SLCAN_OPTIONS = {'sleep_after_open': 0}


def probe(link: ProbeLink) -> list[Attempt]:
    if link.kind != 'can':
        return []
    bitrate = f' at {link.can_bitrate} bit/s' if link.can_bitrate else ''
    return [Attempt(f'listen, then IDS to the turret node{bitrate}',
                    f'can {link.can_interface}:{link.can_channel}',
                    lambda: identify(link))]


def bus_options(link: ProbeLink) -> dict:
    options: dict = dict(SLCAN_OPTIONS) if link.can_interface == 'slcan' else {}
    if link.can_bitrate:
        options['bitrate'] = link.can_bitrate
    return options


def listen(bus: can.BusABC, seconds: float) -> tuple[dict[int, int], int]:
    """Node ids heard sending turret data frames (node id -> frames), and all frames."""
    turret_ids = {i.can_id for i in identifier_table().values()
                  if i.direction is Direction.DATA and i.node_id == TURRET_NODE_ID}
    heard: dict[int, int] = {}
    frames = 0
    deadline = time.monotonic() + seconds
    while (remaining := deadline - time.monotonic()) > 0:
        try:
            frame = bus.recv(timeout=remaining)
        except (can.CanError, ValueError, IndexError):
            continue  # a garbled record from the adapter
        if frame is None:
            break
        frames += 1
        if frame.is_error_frame or frame.is_extended_id or frame.is_remote_frame:
            continue
        try:
            message = CanAerospaceMessage.from_frame(frame.arbitration_id, frame.data)
        except CodecError:
            continue
        if message.can_id in turret_ids:
            heard[message.node_id] = heard.get(message.node_id, 0) + 1
    return heard, frames


def identify(link: ProbeLink) -> Found:
    options = bus_options(link)
    try:
        bus = open_bus(link.can_interface, link.can_channel, **options)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise NoAnswer(f'cannot open CAN interface {link.can_interface}:{link.can_channel}: '
                       f'{exc}') from None
    try:
        heard, frames = listen(bus, link.timeout / 2.0)
    except Exception:
        bus.shutdown()
        raise
    node = max(heard, key=lambda n: heard[n]) if heard else TURRET_NODE_ID
    config = ClientConfig(interface=link.can_interface, channel=link.can_channel,
                          bitrate=link.can_bitrate or None, turret_node_id=node,
                          service_timeout=min(0.1, link.timeout / 6.0), service_attempts=3)
    client = TurretClient(config, bus_factory=lambda _config: bus)
    try:
        client.open()
        info = client.services.identify(node)
    except TurretError as exc:
        heard_text = (f'turret data from node(s) {sorted(heard)}' if heard else
                      f'{frames} frame(s), none a turret data frame')
        raise NoAnswer(f'heard {heard_text} in {link.timeout / 2.0:g} s; no IDS answer from '
                       f'node {node}: {exc}') from None
    finally:
        client.close()  # shuts the bus down
    parameters: dict = {'can_interface': link.can_interface, 'can_channel': link.can_channel,
                        'can_bitrate': link.can_bitrate, 'turret_node_id': node}
    if link.can_interface == 'slcan':
        parameters['can_options'] = [f'{k}={v}' for k, v in SLCAN_OPTIONS.items()]
    notes = [] if heard else ['the bus was silent before the IDS request: the turret may '
                              'not broadcast until a master asks (TIS)']
    if len(heard) > 1:
        notes.append(f'turret data came from several node ids {sorted(heard)}; the busiest '
                     f'({node}) was identified')
    return Found(
        device='CANaerospace turret', protocol='CANaerospace (ICD identifier distribution '
        f'{info.identifier_distribution}, header type {info.header_type})',
        link={'can_interface': link.can_interface, 'can_channel': link.can_channel,
              'can_bitrate': link.can_bitrate or 'as set on the interface'},
        ids={'turret_node_id': node},
        identity={'hardware revision': str(info.hardware_revision),
                  'software revision': str(info.software_revision)},
        parameters=parameters, notes=notes)
