"""The virtual gimbal's line protocol: pure functions, no I/O, no ROS.

One request line -> one reply line (ASCII, ``\\n``-terminated, SI units)::

    ID                     -> ID <model> <serial> <firmware>
    GET                    -> POS <pan> <tilt> <pan_vel> <tilt_vel> <moving_bits> <fault_bits>
    MOVE <joint> <pos> <v> -> OK          (v = 0: default speed)
    JOG <joint> <vel>      -> OK
    STOP [<joint>...]      -> OK
    HOME                   -> OK          (both axes to 0 at default speed)
    RESET                  -> OK          (clears fault bits)
    anything else          -> ERR <reason>

A request may end with a tag, `` #<n>`` (n = 1..65535, chosen by the host); its reply then
ends with the same tag. The device answers a tagged request whenever it is done with it,
so replies may come out of order: a slow request does not hold up the others, and a reply
that comes after its request gave up names itself. An untagged request gets an untagged
reply, in order.

An invented device (no vendor document): it exists so the shared base node is tested
through a real transport without a vendor protocol, and so a new driver has a short,
complete example of the layers (protocol, client, device, node, simulator).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from gimbal_driver_common.errors import GimbalError

JOINTS = ('pan', 'tilt')
#: fault register bit: motor over temperature
FAULT_OVERTEMP = 0x1
FAULT_NAMES = {'overtemp': FAULT_OVERTEMP}
#: request verbs that only read
READS = ('ID', 'GET')
#: request verbs that move or stop an axis
MOTION = ('MOVE', 'JOG', 'STOP', 'HOME')


class ProtocolError(GimbalError):
    """A reply line that does not parse."""


class Refused(GimbalError):
    """An ``ERR`` reply (the device's reason in the message)."""


@dataclass(frozen=True)
class Identity:
    model: str
    serial_number: str
    firmware_version: str


@dataclass(frozen=True)
class Position:
    """A ``POS`` reply: positions and velocities by joint, moving bits, fault bits."""

    positions: dict[str, float]
    velocities: dict[str, float]
    moving: dict[str, bool]
    faults: int


def verb(line: str) -> str:
    """The request verb of a line, upper case ('' for an empty line)."""
    words = line.split()
    return words[0].upper() if words else ''


#: the largest request tag (then the host starts at 1 again)
MAX_TAG = 65535


def tagged(line: str, tag: int) -> str:
    """``line`` with its request tag."""
    return f'{line} #{tag}'


def split_tag(line: str) -> tuple[str, int | None]:
    """A request or reply line without its tag, and the tag (None: untagged)."""
    head, _, last = line.rstrip().rpartition(' ')
    if head and last.startswith('#') and last[1:].isdigit():
        tag = int(last[1:])
        if 1 <= tag <= MAX_TAG:
            return head, tag
    return line.rstrip(), None


def move_request(joint: str, position: float, speed: float | None) -> str:
    return f'MOVE {joint} {position:.6f} {speed or 0.0:.6f}'


def jog_request(joint: str, velocity: float) -> str:
    return f'JOG {joint} {velocity:.6f}'


def stop_request(joints: Sequence[str] | None = None) -> str:
    return ' '.join(['STOP', *(joints or [])])


def check_reply(request: str, reply: str) -> str:
    """The reply, or :class:`Refused` for an ``ERR`` line."""
    if reply.startswith('ERR'):
        raise Refused(f'device refused {request!r}: {reply[4:]}')
    return reply


def parse_identity(reply: str) -> Identity:
    words = reply.split()
    if len(words) != 4 or words[0] != 'ID':
        raise ProtocolError(f'not an ID reply: {reply!r}')
    return Identity(*words[1:])


def parse_position(reply: str) -> Position:
    words = reply.split()
    if len(words) != 7 or words[0] != 'POS':
        raise ProtocolError(f'not a POS reply: {reply!r}')
    try:
        pan, tilt, pan_velocity, tilt_velocity = (float(w) for w in words[1:5])
        moving, faults = int(words[5]), int(words[6])
    except ValueError as exc:
        raise ProtocolError(f'bad POS reply {reply!r}: {exc}') from exc
    return Position({'pan': pan, 'tilt': tilt}, {'pan': pan_velocity, 'tilt': tilt_velocity},
                    {name: bool(moving >> i & 1) for i, name in enumerate(JOINTS)}, faults)


def format_position(positions: Sequence[float], velocities: Sequence[float],
                    moving: Sequence[bool], faults: int) -> str:
    """The simulator's ``POS`` reply."""
    bits = sum(1 << i for i, flag in enumerate(moving) if flag)
    return ('POS ' + ' '.join(f'{v:.6f}' for v in (*positions, *velocities))
            + f' {bits} {faults}')
