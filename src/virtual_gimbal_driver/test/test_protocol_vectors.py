"""The vectors of the virtual gimbal's line protocol: the session in README.md ("Protocol").

The device is invented (no vendor document), so the README's example session is the
specification: each line pair here is in it verbatim (checked), the host's lines are what
the codec writes, the device's what the codec reads back, and the simulator answers each
request with the reply shown.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from virtual_gimbal_driver.protocol import (
    FAULT_OVERTEMP,
    Identity,
    Refused,
    check_reply,
    format_position,
    jog_request,
    move_request,
    parse_identity,
    parse_position,
    split_tag,
    stop_request,
    tagged,
)
from virtual_gimbal_driver.sim import VirtualGimbal

README = Path(__file__).resolve().parent.parent / 'README.md'

#: (request as the host writes it, tag, the reply line as the device writes it)
SESSION = [
    ('ID', 1, 'ID virtual-gimbal VG-0001 1.0.0'),
    ('GET', 2, 'POS 0.100000 -0.200000 0.500000 0.000000 1 0'),
    (move_request('pan', 0.4, None), 3, 'OK'),
    (jog_request('tilt', -0.2), 4, 'OK'),
    (stop_request(), 5, 'OK'),
    (stop_request(['tilt']), 6, 'OK'),
    ('FLY', 7, 'ERR unknown command FLY'),
    ('GET', None, 'POS 0.400000 -0.200000 0.000000 0.000000 0 1'),
]


def line_pair(request: str, tag: int | None, reply: str) -> str:
    def with_tag(line: str) -> str:
        return line if tag is None else tagged(line, tag)

    return f'> {with_tag(request)}\n< {with_tag(reply)}\n'


def test_the_readme_shows_this_session_verbatim() -> None:
    text = README.read_text(encoding='utf-8')
    for vector in SESSION:
        assert line_pair(*vector) in text, f'README.md lacks {line_pair(*vector)!r}'


@pytest.mark.parametrize(('request_line', 'tag', 'reply'), SESSION,
                         ids=[f'{r.split()[0]}-{t}' for r, t, _ in SESSION])
def test_tags_go_on_and_come_off_each_line(request_line: str, tag: int | None,
                                           reply: str) -> None:
    if tag is not None:
        assert split_tag(tagged(request_line, tag)) == (request_line, tag)
        assert split_tag(tagged(reply, tag) + '\n') == (reply, tag)
    else:
        assert split_tag(reply) == (reply, None)


def test_the_host_writes_the_sessions_requests() -> None:
    assert move_request('pan', 0.4, None) == 'MOVE pan 0.400000 0.000000'
    assert move_request('pan', 0.4, 0.0) == 'MOVE pan 0.400000 0.000000'  # 0: default speed
    assert jog_request('tilt', -0.2) == 'JOG tilt -0.200000'
    assert stop_request() == 'STOP' and stop_request(['tilt']) == 'STOP tilt'


def test_the_host_reads_the_sessions_replies() -> None:
    assert parse_identity(SESSION[0][2]) == Identity('virtual-gimbal', 'VG-0001', '1.0.0')
    moving = parse_position(SESSION[1][2])
    assert moving.positions == {'pan': 0.1, 'tilt': -0.2}
    assert moving.velocities == {'pan': 0.5, 'tilt': 0.0}
    assert moving.moving == {'pan': True, 'tilt': False} and moving.faults == 0
    faulted = parse_position(SESSION[-1][2])
    assert faulted.moving == {'pan': False, 'tilt': False}
    assert faulted.faults == FAULT_OVERTEMP
    assert check_reply('MOVE pan', 'OK') == 'OK'
    with pytest.raises(Refused, match="device refused 'FLY': unknown command FLY"):
        check_reply('FLY', SESSION[6][2])


def test_the_simulator_writes_the_sessions_replies() -> None:
    device = VirtualGimbal()
    for request_line, _, reply in SESSION:
        if not reply.startswith('POS'):  # positions depend on the motion: formatted below
            assert device.handle(request_line) == reply, request_line
    assert format_position([0.1, -0.2], [0.5, 0.0], [True, False], 0) == SESSION[1][2]
    assert format_position([0.4, -0.2], [0.0, 0.0], [False, False],
                           FAULT_OVERTEMP) == SESSION[-1][2]
