"""The session base over a real TCP loopback link: a line protocol with requests,
notifications, garbage, a silent peer, link loss mid-request and clean shutdown."""

from __future__ import annotations

import socket
import threading

import pytest

from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout, LinkError
from gimbal_driver_common.session import Protocol, Session, StreamLink
from gimbal_driver_common.transport import TcpStream


class Answer(str):
    """``ANS <id> <text>``: the reply to ``REQ <id>``."""


class Note(str):
    """``NOTE <text>``: an unsolicited notification."""


class Refusal(str):
    """``NAK <id>``: the device refused request ``<id>``."""


class LineProtocol(Protocol):
    """Lines in, typed messages out; records what the session told it."""

    def __init__(self) -> None:
        self.buffer = b''
        self.garbage: list[bytes] = []
        self.made = threading.Event()
        self.lost: list[LinkError | None] = []
        self.ended = threading.Event()

    def connection_made(self, session: Session) -> None:
        self.session = session
        self.made.set()

    def data_received(self, data: bytes) -> None:
        self.buffer += data
        *lines, self.buffer = self.buffer.split(b'\n')
        for line in lines:
            kind, _, rest = line.decode('ascii', 'replace').partition(' ')
            message = {'ANS': Answer, 'NOTE': Note, 'NAK': Refusal}.get(kind)
            if message is None:
                self.garbage.append(line)
                continue
            self.session.dispatch(message(rest))

    def connection_lost(self, error: LinkError | None) -> None:
        self.lost.append(error)
        self.ended.set()


def reply_to(request_id: str):
    def match(message):
        if isinstance(message, Refusal) and message == request_id:
            return DeviceRefused(f'request {request_id} refused')
        return isinstance(message, Answer) and message.split(' ')[0] == request_id
    return match


@pytest.fixture
def link():
    """(client session, protocol, the device's end of the connection)."""
    listener = socket.create_server(('127.0.0.1', 0))
    stream = TcpStream('127.0.0.1', listener.getsockname()[1])
    stream.open()
    device, _ = listener.accept()
    listener.close()
    protocol = LineProtocol()
    session = Session(StreamLink(stream), protocol, 'test').start()
    yield session, protocol, device
    session.close()
    device.close()


def serve(device: socket.socket, respond) -> threading.Thread:
    """Answer each request line the device receives with ``respond(line)`` bytes."""
    def run() -> None:
        buffer = b''
        while True:
            try:
                data = device.recv(4096)
            except OSError:
                return
            if not data:
                return
            buffer += data
            *lines, buffer = buffer.split(b'\n')
            for line in lines:
                answer = respond(line.decode())
                if answer:
                    device.sendall(answer)
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_replies_are_matched_to_their_requests(link) -> None:
    session, _protocol, device = link
    # the device answers out of order, with another request's answer first
    serve(device, lambda line: f'ANS 99 other\nANS {line.split()[1]} ok-{line.split()[1]}\n'
          .encode())
    assert session.request(b'REQ 1\n', reply_to('1'), 2.0) == '1 ok-1'
    assert session.request(b'REQ 2\n', reply_to('2'), 2.0) == '2 ok-2'


def test_a_refusal_raises_the_matchers_error(link) -> None:
    session, _protocol, device = link
    serve(device, lambda line: f'NAK {line.split()[1]}\n'.encode())
    with pytest.raises(DeviceRefused, match='request 7 refused'):
        session.request(b'REQ 7\n', reply_to('7'), 2.0)


def test_notifications_go_to_their_handler_and_garbage_is_skipped(link) -> None:
    session, protocol, device = link
    notes: list[str] = []
    got_two = threading.Event()

    def on_note(note: Note) -> None:
        notes.append(str(note))
        if len(notes) == 2:
            got_two.set()

    session.on(Note, on_note)
    session.on(Answer, lambda _answer: 1 / 0)  # a broken handler does not end the session
    device.sendall(b'NOTE first\n\xff\xfe junk\nANS 5 x\nNOTE second\n')
    assert got_two.wait(2.0)
    assert notes == ['first', 'second']
    assert protocol.garbage == [b'\xff\xfe junk']
    serve(device, lambda line: b'ANS 6 fine\n')
    assert session.request(b'REQ 6\n', reply_to('6'), 2.0) == '6 fine'
    assert session.alive


def test_a_silent_device_gives_device_timeout(link) -> None:
    session, _protocol, device = link
    with pytest.raises(DeviceTimeout, match='no answer'):
        session.request(b'REQ 3\n', reply_to('3'), 0.2)
    assert device.recv(100) == b'REQ 3\n'
    assert session.alive


def test_link_loss_mid_request_fails_it_once_with_link_error(link) -> None:
    session, protocol, device = link
    outcome: list[BaseException] = []

    def ask() -> None:
        try:
            session.request(b'REQ 4\n', reply_to('4'), 30.0)
        except BaseException as exc:  # noqa: BLE001 - recorded for the assertion
            outcome.append(exc)

    asker = threading.Thread(target=ask)
    asker.start()
    assert device.recv(100) == b'REQ 4\n'
    device.close()
    asker.join(5.0)
    assert not asker.is_alive()
    assert len(outcome) == 1 and isinstance(outcome[0], LinkError)
    assert protocol.ended.wait(2.0)
    assert protocol.lost == [session.error] and session.error is not None
    assert not session.alive
    with pytest.raises(LinkError):
        session.write(b'REQ 5\n')
    session.lose('again')
    assert protocol.lost == [session.error]


def test_a_protocol_may_give_the_link_up_from_its_tick() -> None:
    listener = socket.create_server(('127.0.0.1', 0))
    stream = TcpStream('127.0.0.1', listener.getsockname()[1])
    stream.open()
    device, _ = listener.accept()
    listener.close()

    class Silent(LineProtocol):
        def tick(self, now: float) -> float | None:
            raise LinkError('no telemetry')

    protocol = Silent()
    session = Session(StreamLink(stream), protocol, 'silence').start()
    try:
        assert protocol.ended.wait(2.0)
        assert [str(error) for error in protocol.lost] == ['no telemetry']
        assert not stream.is_open
    finally:
        session.close()
        device.close()


def test_close_ends_the_reader_closes_the_link_and_fails_pending_requests(link) -> None:
    session, protocol, device = link
    outcome: list[BaseException] = []

    def ask() -> None:
        try:
            session.request(b'REQ 8\n', reply_to('8'), 30.0)
        except BaseException as exc:  # noqa: BLE001 - recorded for the assertion
            outcome.append(exc)

    asker = threading.Thread(target=ask)
    asker.start()
    assert device.recv(100) == b'REQ 8\n'
    reader = session.reader
    assert reader is not None and reader.name == 'test-reader'
    session.close()
    asker.join(5.0)
    assert not reader.is_alive()
    assert not any(thread.name == 'test-reader' for thread in threading.enumerate())
    assert len(outcome) == 1 and isinstance(outcome[0], LinkError)
    assert protocol.lost == [None] and session.error is None
    assert device.recv(100) == b''  # the link was closed
    session.close()


def test_over_a_pty_garbage_is_skipped_and_the_device_going_away_is_one_loss() -> None:
    """The same session over a serial link (a pseudo-terminal): the device end closing is
    a read failure, reported once, and the reader closes the port."""
    import os
    import tty

    from gimbal_driver_common.transport import SerialStream

    device, port = os.openpty()
    tty.setraw(device)
    stream = SerialStream(os.ttyname(port))
    stream.open()
    os.close(port)  # the client's stream has its own descriptor
    protocol = LineProtocol()
    notes: list[str] = []
    session = Session(StreamLink(stream), protocol, 'pty')
    session.on(Note, lambda note: notes.append(str(note)))
    session.start()
    try:
        os.write(device, b'\x00\x01 noise\nNOTE over serial\n')
        assert protocol.made.is_set()

        def answer() -> None:
            request = b''
            while not request.endswith(b'\n'):
                request += os.read(device, 100)
            os.write(device, b'ANS 9 serial\n')

        threading.Thread(target=answer, daemon=True).start()
        assert session.request(b'REQ 9\n', reply_to('9'), 2.0) == '9 serial'
        assert notes == ['over serial']
        assert protocol.garbage == [b'\x00\x01 noise']
        os.close(device)
        device = -1
        assert protocol.ended.wait(2.0)
        assert len(protocol.lost) == 1 and isinstance(protocol.lost[0], LinkError)
        assert not stream.is_open
    finally:
        session.close()
        if device >= 0:
            os.close(device)
