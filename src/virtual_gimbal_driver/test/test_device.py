"""GimbalController + VirtualGimbalDevice against the simulator in-process, over its real
TCP link; no ROS (ARCHITECTURE.md, "Adding a driver", item 4).

Waits are "up to a timeout" for a condition, never timing assertions.
"""

from __future__ import annotations

import contextlib
import logging
import math
import socket
import threading
import tracemalloc

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout, LinkError
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_testing import wait_for
from virtual_gimbal_driver.client import VirtualGimbalClient
from virtual_gimbal_driver.device import MISSED_POLLS_LOST, VirtualGimbalDevice
from virtual_gimbal_driver.protocol import (
    MAX_TAG,
    move_request,
    parse_position,
    split_tag,
    tagged,
    verb,
)
from virtual_gimbal_driver.sim import make_server

LOG = logging.getLogger('test_device')
JOINTS = ['pan', 'tilt']


def took(axis: dict, target: float) -> bool:
    """The simulated axis took a move to ``target``: on its way there, or already arrived
    (the model forgets a target it reached; a short move ends within one poll of a loaded
    test machine)."""
    if axis['target'] is None:
        return axis['position'] == pytest.approx(target)
    return axis['target'] == pytest.approx(target)


class Rig:
    """The simulator's TCP server, the adapter and a started controller."""

    def __init__(self, muted: tuple[str, ...] = (), request_timeout: float = 1.0) -> None:
        self.server, self.sim = make_server()
        for name in muted:  # the simulator's mute VERB: received, never answered
            self.sim.request_faults.mute(name)
        self.device = VirtualGimbalDevice('127.0.0.1', self.server.port,
                                          request_timeout=request_timeout)
        config = ControllerConfig(
            joint_names=list(JOINTS),
            limits={'pan': JointLimits(-math.pi, math.pi, 1.5),
                    'tilt': JointLimits(-math.pi / 2, math.pi / 2, 1.5)},
            publish_rate=50.0, command_timeout=0.3, reconnect_period=0.1,
            goal_tolerance=1e-3, move_timeout=10.0)
        self.controller = GimbalController(self.device, config, LOG)
        self.controller.open()
        self.controller.activate()
        wait_for(lambda: self.controller.latest is not None, 10.0, 'a first sample')

    def axis(self, joint: str) -> dict:
        return self.sim.state()['axes'][joint]

    def took(self, joint: str, target: float) -> bool:
        return took(self.axis(joint), target)

    def close(self) -> None:
        self.controller.shutdown()
        self.server.stop()


@pytest.fixture
def rig():
    started = Rig()
    yield started
    started.close()


def test_identity_and_samples_come_from_the_device(rig):
    info = rig.controller.device_info
    assert (info.model, info.serial_number, info.firmware_version) == (
        'virtual-gimbal', 'VG-0001', '1.0.0')
    assert rig.controller.positions() == {'pan': 0.0, 'tilt': 0.0}


def test_a_joint_command_reaches_the_device_and_the_samples(rig):
    rig.controller.command(['pan', 'tilt'], [0.3, -0.2], [])
    wait_for(lambda: rig.took('pan', 0.3), 5.0, 'the pan target')
    wait_for(lambda: abs(rig.controller.positions()['tilt'] + 0.2) < 1e-3, 10.0,
             'tilt at -0.2 in the samples')
    assert rig.controller.commanded_targets == {'pan': 0.3, 'tilt': -0.2}


def test_a_jog_stops_when_its_commands_stop_coming(rig):
    rig.controller.command(['pan'], [], [0.4])
    wait_for(lambda: rig.axis('pan')['velocity'] > 0.1, 5.0, 'the jog at the device')
    wait_for(lambda: rig.axis('pan')['velocity'] == 0.0, 5.0, 'the dead-man stop')
    assert rig.controller.watchdog.jogging == []


def test_stop_halts_a_move(rig):
    rig.controller.command(['pan'], [3.0], [0.5])
    wait_for(lambda: rig.axis('pan')['velocity'] > 0.1, 5.0, 'the move under way')
    assert rig.controller.stop().startswith('all axes stopped')
    wait_for(lambda: rig.axis('pan')['velocity'] == 0.0, 5.0, 'the axis stopped')
    assert rig.axis('pan')['position'] < 2.0


def test_a_refused_request_is_counted_with_the_devices_answer(rig):
    rig.sim.control_nack(['MOVE'])
    rig.controller.command(['pan'], [0.1], [])
    wait_for(lambda: rig.controller.rejections.counts()['refused'].get(
        'failed on the device: refused by the device'), 5.0, 'the refusal counted')
    rig.controller.command(['pan'], [0.1], [])  # the next one is carried out
    wait_for(lambda: rig.took('pan', 0.1), 5.0, 'the move')


def test_fault_bits_are_decoded_and_reset_clears_them(rig):
    rig.sim.control_fault(['overtemp'])
    wait_for(lambda: rig.device.errors() == ['overtemperature'], 5.0, 'the fault decoded')
    assert rig.controller.reset_faults() == 'faults cleared'
    wait_for(lambda: rig.device.errors() == [], 5.0, 'the fault cleared')


def test_a_dropped_link_is_reported_and_reopened(rig):
    connects = rig.controller.reconnects
    rig.server.drop_link()
    wait_for(lambda: rig.controller.reconnects > connects and rig.controller.connected, 10.0,
             'the link reopened')
    rig.controller.command(['tilt'], [0.25], [])
    wait_for(lambda: rig.took('tilt', 0.25), 5.0,
             'a command after the reconnect')


def test_posted_replies_are_taken_by_tag_with_requests_in_between():
    """post() writes and returns; requests go on meanwhile and each gets the reply with its
    own tag; settle() then takes the posted replies and raises the device's ERR to one of
    them."""
    server, sim = make_server()
    client = VirtualGimbalClient('127.0.0.1', server.port)
    try:
        client.open()
        posted = client.post([move_request('pan', 0.2, 0.5), 'BOGUS'])
        assert parse_position(client.request('GET')).positions['pan'] < 0.2  # its own reply
        with pytest.raises(DeviceRefused, match='unknown command BOGUS'):
            client.settle(posted)
        assert took(sim.state()['axes']['pan'], 0.2)
        posted = client.post([move_request('tilt', -0.1, 0.5)])
        client.request('GET')
        client.settle(posted)
        assert took(sim.state()['axes']['tilt'], -0.1)
    finally:
        client.close()
        server.stop()


def test_a_reply_comes_to_its_request_while_a_slow_one_waits():
    """Tags let replies come out of order: with HOME's reply held back (the simulator's
    ``delay``), a GET and a STOP sent meanwhile are answered at once."""
    server, sim = make_server()
    client = VirtualGimbalClient('127.0.0.1', server.port, timeout=10.0)
    sim.request_faults.delay('HOME', 5.0)
    homed: list[str] = []
    try:
        client.open()
        client.request(move_request('pan', 0.3, 0.0))
        wait_for(lambda: sim.state()['axes']['pan']['position'] == pytest.approx(0.3), 5.0,
                 'pan at 0.3')
        def home() -> None:
            with contextlib.suppress(LinkError):  # the client closes before HOME's reply
                homed.append(client.request('HOME'))

        homing = threading.Thread(target=home, daemon=True)
        homing.start()
        wait_for(lambda: sim.state()['axes']['pan']['position'] < 0.29, 5.0,
                 'HOME acted on (its reply held back)')
        assert client.request('STOP') == 'OK'
        assert client.request('GET').startswith('POS')
        assert homed == []  # HOME's reply is still held
        sim.request_faults.clear()
    finally:
        client.close()
        server.stop()


def test_a_command_stream_is_written_from_the_callback(rig):
    """With the link free, a move goes out from the caller's thread (Device.post) and the
    command thread reads its OK; a refused posted move is counted like any refusal."""
    post, nack = rig.device.client.post, False
    posted: list[tuple[list[str], int]] = []  # lines, refusals counted when they went out

    def total_refused() -> int:
        return sum(rig.controller.rejections.counts()['refused'].values())

    def spy(lines: list[str]) -> bool:
        if nack and not rig.sim.nack_pending:
            rig.sim.control_nack(['MOVE'])  # the next MOVE line: this one if it goes out
        written = post(lines)
        if written:
            posted.append((lines, total_refused()))
        return written

    rig.device.client.post = spy
    targets = iter(0.01 * k for k in range(1, 1000))

    def stream_until_posted() -> bool:
        if not posted:
            rig.controller.command(['pan'], [next(targets)], [])
        return bool(posted)

    wait_for(stream_until_posted, 10.0, 'a move posted (the link free)')
    target = float(posted[0][0][0].split()[2])
    wait_for(lambda: rig.controller.commanded_targets.get('pan') == target, 5.0,
             'its OK read')
    assert rig.took('pan', target)
    assert total_refused() == 0
    # a post goes out only while no other send runs, and the stream stops at the first
    # one: a refusal counted after it is the posted move's
    nack = True
    posted.clear()
    wait_for(stream_until_posted, 10.0, 'a move posted to the refusing device')
    wait_for(lambda: total_refused() > posted[0][1], 5.0, 'the posted move refused')




def test_bytes_no_request_asked_for_are_discarded_with_a_warning(caplog) -> None:
    """Noise (or a reply after its timeout) waiting on the link is not taken for the next
    request's reply: the client drops it and says so (virtual_gimbal_driver.client). A bare
    socket plays the device, so the noise is on the link before the request goes out."""
    listener = socket.create_server(('127.0.0.1', 0))
    client = VirtualGimbalClient('127.0.0.1', listener.getsockname()[1])
    client.open()
    device, _ = listener.accept()

    def answer() -> None:
        with contextlib.suppress(OSError):
            for line in device.makefile('rb'):
                text, tag = split_tag(line.decode())
                reply = 'ID model serial 1.0' if text.startswith('ID') else 'OK'
                device.sendall((tagged(reply, tag) + '\n').encode())

    threading.Thread(target=answer, daemon=True).start()
    try:
        assert client.request('ID') == 'ID model serial 1.0'
        with caplog.at_level(logging.WARNING, logger='virtual_gimbal_driver.client'):
            device.sendall(b'NOISE\nOK #999\n')  # no request has these tags
            assert client.request('ID') == 'ID model serial 1.0'
            assert client.request('STOP') == 'OK'
            wait_for(lambda: len([r for r in caplog.records
                                  if r.name == 'virtual_gimbal_driver.client']) == 2, 5.0,
                     'both lines discarded')
        records = [r for r in caplog.records if r.name == 'virtual_gimbal_driver.client']
        assert all(r.levelno == logging.WARNING for r in records)
        assert "NOISE" in records[0].getMessage() and "OK #999" in records[1].getMessage()
    finally:
        client.close()
        device.close()
        listener.close()


def test_an_unanswered_id_never_keeps_the_device_from_connecting(caplog):
    """ID is identity only: unanswered, a WARN and a diagnostics key; the node connects
    and moves (request_timeout sets how long the link waits for it)."""
    with caplog.at_level(logging.WARNING):
        rig = Rig(muted=('ID',), request_timeout=0.2)
    try:
        assert 'ID unanswered at connect' in caplog.text
        assert rig.controller.device_info.model == 'virtual gimbal (ID unanswered)'
        [part] = rig.device.parts()
        assert part.level == 1 and 'unanswered.ID' in dict(part.values), part
        rig.controller.command(['pan'], [0.2], [])
        wait_for(lambda: rig.took('pan', 0.2), 5.0, 'the pan target')
    finally:
        rig.close()


def test_unanswered_joint_data_names_itself():
    """GET is what the node cannot work without: connecting fails and names it."""
    server, sim = make_server()
    sim.request_faults.mute('GET')
    device = VirtualGimbalDevice('127.0.0.1', server.port, request_timeout=0.2)
    try:
        with pytest.raises(DeviceTimeout, match=r'no reply to GET within 0\.2 s'):
            device.open()
    finally:
        device.close()
        server.stop()


def mute_one_get(rig: Rig) -> None:
    """The simulator drops the next GET it receives and answers the ones after it (the
    mute is lifted on the simulator's own thread, as that GET is dropped)."""
    handle = rig.sim.handle

    def handle_then_unmute(line: str) -> str | None:
        reply = handle(line)
        if reply is None and verb(line) == 'GET':
            rig.sim.request_faults.mute('GET', False)
        return reply

    rig.sim.handle = handle_then_unmute  # type: ignore[method-assign]  # a test's spy
    rig.sim.request_faults.mute('GET')


def test_one_unanswered_poll_skips_a_sample_and_keeps_the_link(caplog):
    """A GET answered late once (a loaded or paused machine) costs one sample and a WARN,
    not the link: the next poll is answered and the controller never reconnects."""
    rig = Rig(request_timeout=0.2)
    try:
        connects, sample = rig.controller.reconnects, rig.controller.latest
        with caplog.at_level(logging.WARNING):
            mute_one_get(rig)
            wait_for(lambda: 'poll skipped: no reply to GET within 0.2 s' in caplog.text, 5.0,
                     'the skipped poll named')
        wait_for(lambda: rig.controller.latest is not sample and not rig.sim.request_faults
                 .muted('GET'), 5.0, 'samples again')
        newer = rig.controller.latest
        wait_for(lambda: rig.controller.latest is not newer, 5.0, 'a sample after it')
        assert rig.controller.connected and rig.controller.reconnects == connects
        assert 'link lost' not in caplog.text
    finally:
        rig.close()


def test_polls_unanswered_in_a_row_lose_the_link(caplog):
    rig = Rig(request_timeout=0.2)
    try:
        with caplog.at_level(logging.WARNING):
            rig.sim.request_faults.mute('GET')
            wait_for(lambda: not rig.controller.connected, 5.0, 'the link lost')
        assert (f'device link lost (no reply to GET within 0.2 s ({MISSED_POLLS_LOST} polls '
                'in a row))') in caplog.text
    finally:
        rig.close()


def test_request_tags_wrap_at_max_tag_and_hold_no_history() -> None:
    """Tags run 1..MAX_TAG and round again, and handing one out keeps nothing: the client
    once drew them from an itertools.cycle, which stores every value it gives until it
    wraps (65,535 ints: 2.6 MB grown by one a poll, 22 minutes at 50 Hz)."""
    client = VirtualGimbalClient('127.0.0.1', 9)  # never connected: tags need no link

    def one_tag() -> int:
        tag = client._tag()
        client._done([tag])
        return tag

    tracemalloc.start()
    try:
        warm = [one_tag() for _ in range(100)]
        before, _ = tracemalloc.get_traced_memory()
        for _ in range(30_000):
            one_tag()
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert warm[:3] == [1, 2, 3]
    assert grown < 64_000, f'{grown} bytes kept by 30,000 tags'
    tags = [one_tag() for _ in range(MAX_TAG - 30_100 + 2)]
    assert tags[-3:] == [MAX_TAG, 1, 2]
