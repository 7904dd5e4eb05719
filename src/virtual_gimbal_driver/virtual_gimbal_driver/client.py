"""The virtual gimbal's session: tagged request lines, each answered by the reply line with
its tag, on one reader thread (no ROS).

The link has one owner of its input, the reader thread ``vgimbal-reader`` (the core's
session base, :class:`gimbal_driver_common.session.Session`, as every driver has): it
splits what arrives into lines and gives each reply to the request whose tag it carries.
Callers write their request and wait for their own answer, so requests overlap: a slow or
silent one (a HOME the device takes long to acknowledge) holds up nothing else, and a
stop goes out at once. :meth:`VirtualGimbalClient.post` writes requests whose replies
:meth:`VirtualGimbalClient.settle` takes later (the core's command path);
:meth:`VirtualGimbalClient.ask` writes one whose reply the reader hands to a callback (the
joint poll: the sample is taken on the reader thread, with no thread woken to wait for it).

It logs through :mod:`logging` (``virtual_gimbal_driver.client``), as every driver's
library code does; the node's log bridge (``gimbal_driver_common.ros.log_bridge``) takes
the lines to the node's ROS logger and /rosout.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from gimbal_driver_common.errors import DeviceRefused, LinkError
from gimbal_driver_common.session import Pending, Protocol, Session, StreamLink
from gimbal_driver_common.transport import ByteStream, TcpStream

from .protocol import MAX_TAG, Refused, check_reply, split_tag, tagged, verb

LOG = logging.getLogger(__name__)
#: how many characters of a discarded line a warning shows
SHOWN_BYTES = 40
#: a line longer than this without a newline is noise: dropped
MAX_LINE = 4096


@dataclass(frozen=True)
class Reply:
    """One reply line and the tag it carries."""

    text: str
    tag: int


def answers(tag: int) -> Callable[[Reply], bool]:
    """The match of the request with ``tag``: its reply names it."""
    return lambda reply: reply.tag == tag


@dataclass
class Posted:
    """Requests written by :meth:`VirtualGimbalClient.post`, waiting for their replies."""

    lines: list[str]
    tags: list[int]
    pendings: list[Pending[Reply]]
    session: Session
    written_at: float


class VirtualGimbalClient(Protocol):
    """Request/reply client (thread-safe): every request carries a tag, and the reader
    gives each reply to the request it names."""

    def __init__(self, host: str, port: int, timeout: float = 1.0) -> None:
        self.host, self.port = host, port
        #: the link (a probe may wrap it to watch the bytes)
        self.stream: ByteStream = TcpStream(host, port)
        self.timeout = timeout
        self._session: Session | None = None
        self._buffer = b''
        #: the tag of the next request, 1 to MAX_TAG and round again (a counter, not an
        #: itertools.cycle: a cycle keeps every value it gave until it wraps, 65,535 ints,
        #: 2.6 MB grown at one a poll over the first 22 minutes at 50 Hz)
        self._next_tag = 1
        self._lock = threading.Lock()
        #: tags written and not answered yet (a reply naming another is discarded)
        self._waiting: set[int] = set()
        #: what the reader calls with the reply to an :meth:`ask`, by tag
        self._callbacks: dict[int, Callable[[Reply], None]] = {}

    def open(self) -> None:
        self.close()
        self.stream.open()
        self._buffer = b''
        with self._lock:
            self._waiting.clear()
            self._callbacks.clear()
        self._session = Session(StreamLink(self.stream), self, 'vgimbal',
                                read_timeout=0.05).start()

    def close(self) -> None:
        session, self._session = self._session, None
        if session is not None:
            session.close()  # the reader closes the stream as it ends
        else:
            self.stream.close()

    def request(self, line: str) -> str:
        """Send ``line``; the reply line, DeviceRefused for ERR, DeviceTimeout for none."""
        session = self._live()
        tag = self._tag()
        try:
            with session.expect(answers(tag)) as pending:
                session.write((tagged(line, tag) + '\n').encode())
                reply = pending.next(self.timeout, f'reply to {verb(line)}')
        finally:
            self._done([tag])
        return self._checked(line, reply)

    def post(self, lines: Sequence[str]) -> Posted:
        """Write ``lines`` in one write without waiting for their replies; returns what
        :meth:`settle` takes."""
        session = self._live()
        tags = [self._tag() for _ in lines]
        pendings = [session.register(answers(tag)) for tag in tags]
        try:
            session.write(b''.join((tagged(line, tag) + '\n').encode()
                                   for line, tag in zip(lines, tags, strict=True)))
        except BaseException:
            self._forget(session, pendings, tags)
            raise
        return Posted(list(lines), tags, pendings, session, time.monotonic())

    def settle(self, posted: Posted) -> None:
        """Take the replies of a :meth:`post`; raise the first ERR among them
        (DeviceRefused), or the timeout or lost link that cut them off."""
        if posted.session is not self._session:
            raise LinkError(f'link lost before the reply to {verb(posted.lines[0])}')
        refused: DeviceRefused | None = None
        try:
            for line, pending in zip(posted.lines, posted.pendings, strict=True):
                remaining = posted.written_at + self.timeout - time.monotonic()
                reply = pending.next(remaining, f'reply to {verb(line)}')
                try:
                    self._checked(line, reply)
                except DeviceRefused as exc:
                    refused = refused or exc
        finally:
            self._forget(posted.session, posted.pendings, posted.tags)
        if refused is not None:
            raise refused

    def ask(self, line: str, on_reply: Callable[[Reply], None]) -> int:
        """Write ``line`` without waiting: the reader thread calls ``on_reply`` with its
        reply (an ERR line too) when it comes. Returns the tag, for :meth:`forget`
        when the reply is given up."""
        session = self._live()
        tag = self._tag()
        with self._lock:
            self._callbacks[tag] = on_reply
        try:
            session.write((tagged(line, tag) + '\n').encode())
        except BaseException:
            self.forget(tag)
            raise
        return tag

    def forget(self, tag: int) -> None:
        """Give up the reply to an :meth:`ask`: if it still comes, it is discarded."""
        with self._lock:
            self._callbacks.pop(tag, None)
            self._waiting.discard(tag)

    # ------------------------------------------------- the reader (Protocol)
    def data_received(self, data: bytes) -> None:
        self._buffer += data
        while b'\n' in self._buffer:
            raw, self._buffer = self._buffer.split(b'\n', 1)
            text, tag = split_tag(raw.decode('ascii', 'replace'))
            callback = None
            with self._lock:
                asked = tag is not None and tag in self._waiting
                if asked and tag is not None:
                    callback = self._callbacks.pop(tag, None)
                    if callback is not None:
                        self._waiting.discard(tag)
            if not asked or tag is None:
                LOG.warning('discarded a line that no request asked for (noise, or a reply '
                            'after its timeout): %r', raw[:SHOWN_BYTES])
                continue
            if callback is not None:
                try:
                    callback(Reply(text, tag))
                except Exception:  # a handler bug must not end the session
                    LOG.exception('error while handling the reply %r', raw[:SHOWN_BYTES])
                continue
            session = self._session
            if session is not None:
                session.dispatch(Reply(text, tag))
        if len(self._buffer) > MAX_LINE:
            LOG.warning('discarded %d bytes without a newline', len(self._buffer))
            self._buffer = b''

    # ------------------------------------------------------------- helpers
    def _live(self) -> Session:
        session = self._session
        if session is None or not session.alive:
            raise LinkError(f'{self.stream.description}: not connected'
                            + (f' ({session.error})' if session and session.error else ''))
        return session

    def _tag(self) -> int:
        with self._lock:
            tag = self._next_tag
            self._next_tag = tag % MAX_TAG + 1
            self._waiting.add(tag)
            return tag

    def _done(self, tags: Sequence[int]) -> None:
        with self._lock:
            self._waiting.difference_update(tags)

    def _forget(self, session: Session, pendings: list[Pending[Reply]],
                tags: Sequence[int]) -> None:
        for pending in pendings:
            session.unregister(pending)
        self._done(tags)

    @staticmethod
    def _checked(line: str, reply: Reply) -> str:
        return VirtualGimbalClient.checked(line, reply.text)

    @staticmethod
    def checked(line: str, text: str) -> str:
        """The reply ``text`` to ``line``; DeviceRefused for an ERR line."""
        try:
            return check_reply(line, text)
        except Refused as exc:
            raise DeviceRefused(str(exc)) from None
