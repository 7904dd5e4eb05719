"""One session base for the clients of devices that stream: one reader thread per link.

Modelled on pyserial's ``serial.threaded``: a :class:`Protocol` is driven by the one reader
thread of a :class:`Session` (``connection_made``, ``data_received``, ``connection_lost``),
plus a ``tick`` for the periodic work of a session (a refresh, a poll, a silence check) so
that it needs no thread of its own. The client decodes what arrives into messages in its
protocol and hands each to :meth:`Session.dispatch`, the one way to answer requests and
notify: the handler registered for the message's type runs first (it updates the client's
state), then every pending request whose ``match`` accepts the message gets it.

A link is anything with ``read(timeout)``, ``write(data)`` and ``close()``
(:class:`Link`): a :class:`~gimbal_driver_common.transport.ByteStream` through
:class:`StreamLink`, a python-can bus, a USB HID device. Its loss (a read or write that
fails, or a protocol that raises :class:`LinkError`) is reported once: pending requests
fail with it, the reader closes the link and ends, and ``connection_lost`` gets the error.
:meth:`Session.close` is the one shutdown: it stops the reader, which closes the link,
and fails what is still pending. No reconnecting here: the controller's supervisor opens a
new session.
"""

from __future__ import annotations

import abc
import collections
import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, Generic, TypeVar

from gimbal_driver_common.errors import DeviceTimeout, LinkError
from gimbal_driver_common.transport import ByteStream

LOG = logging.getLogger('gimbal_driver_common.session')

M = TypeVar('M')

#: what a request's ``match`` says of a message: True (the answer), False (not for this
#: request) or an exception (the device refused it: the request raises that)
Match = Callable[[Any], 'bool | BaseException']


class Link(abc.ABC):
    """What a session reads and writes: one device link."""

    description = ''

    @abc.abstractmethod
    def read(self, timeout: float) -> Any:
        """What arrived within ``timeout`` s (bytes, a frame), a false value if nothing
        did; raises :class:`LinkError` (or OSError) when the link is gone."""

    @abc.abstractmethod
    def write(self, data: Any) -> None:
        """Send ``data``; raises :class:`LinkError` (or OSError) when the link is gone."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the link (called once, by the reader thread as it ends)."""


class StreamLink(Link):
    """A :class:`ByteStream` (TCP, serial, pty, USB HID) as a session's link."""

    def __init__(self, stream: ByteStream, chunk: int = 4096) -> None:
        self.stream = stream
        self.chunk = chunk
        self.description = stream.description

    def read(self, timeout: float) -> bytes:
        return self.stream.read(self.chunk, timeout)

    def write(self, data: bytes) -> None:
        self.stream.write(data)

    def close(self) -> None:
        self.stream.close()


class Protocol:
    """The client's side of a session (pyserial's ``serial.threaded.Protocol``).

    Every method runs on the session's reader thread, except ``connection_made`` (on the
    thread that starts the session, before the reader starts).
    """

    def connection_made(self, session: Session) -> None:
        """The session is about to start reading ``session.link``."""

    def data_received(self, data: Any) -> None:
        """Decode ``data`` (what the link's read gave) and :meth:`Session.dispatch` each
        message. Raise :class:`LinkError` to give the link up; anything else is logged and
        the session goes on (garbage and handler bugs do not end a session)."""

    def tick(self, now: float) -> float | None:
        """Periodic work at monotonic ``now``; returns when to be called next (None: at the
        reader's own pace). Raise :class:`LinkError` to give the link up (a silence)."""
        return None

    def connection_lost(self, error: LinkError | None) -> None:
        """The session ended: ``error`` when the link was lost, None when closed."""


class Pending(Generic[M]):
    """A request's place in the session: the messages that ``match`` accepted, in order."""

    def __init__(self, match: Match) -> None:
        self.match = match
        self._messages: collections.deque[M] = collections.deque()
        self._error: BaseException | None = None
        self._condition = threading.Condition()

    def offer(self, message: M) -> None:
        verdict = self.match(message)
        if verdict is False or verdict is None:
            return
        with self._condition:
            if isinstance(verdict, BaseException):
                self._error = verdict
            else:
                self._messages.append(message)
            self._condition.notify_all()

    def fail(self, error: BaseException) -> None:
        with self._condition:
            if self._error is None:
                self._error = error
            self._condition.notify_all()

    def next(self, timeout: float, what: str = 'answer') -> M:
        """The next accepted message; DeviceTimeout after ``timeout`` s without one, the
        refusal or the link error when one came first."""
        with self._condition:
            self._condition.wait_for(lambda: self._messages or self._error is not None,
                                     max(timeout, 0.0))
            if self._messages:
                return self._messages.popleft()
            if self._error is not None:
                raise self._error
        raise DeviceTimeout(f'no {what} within {timeout:g} s')

    def drain(self) -> list[M]:
        with self._condition:
            messages = list(self._messages)
            self._messages.clear()
            return messages


class Session:
    """One link, its reader thread, its pending requests and its notification handlers."""

    def __init__(self, link: Link, protocol: Protocol, name: str, *,
                 read_timeout: float = 0.05,
                 link_error: type[LinkError] = LinkError) -> None:
        self.link = link
        self.protocol = protocol
        self.name = name
        self.read_timeout = read_timeout
        self.link_error = link_error
        self.error: LinkError | None = None  # why the link was lost (None: up or closed)
        self._handlers: dict[type, Callable[[Any], None]] = {}
        self._pending: list[Pending[Any]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._reader: threading.Thread | None = None

    # --- lifecycle --------------------------------------------------------------
    def start(self) -> Session:
        """``connection_made``, then the reader thread ``<name>-reader``."""
        self.protocol.connection_made(self)
        self._reader = threading.Thread(target=self._run, name=f'{self.name}-reader',
                                        daemon=True)
        self._reader.start()
        return self

    @property
    def alive(self) -> bool:
        """True until the link is lost or the session closed."""
        return not self._stop.is_set()

    @property
    def reader(self) -> threading.Thread | None:
        return self._reader

    def close(self, timeout: float = 2.0) -> None:
        """The one shutdown: stop reading, close the link (the reader does, as it ends),
        fail what is pending. Safe to call twice and from a handler."""
        self._stop.set()
        reader = self._reader
        if reader is None:
            self._close_link()
        elif reader is not threading.current_thread():
            reader.join(timeout)
            if reader.is_alive():  # a read that does not time out: close under it
                self._close_link()
        self._fail_pending(self.error or self.link_error(f'{self.link.description}: '
                                                         'the session was closed'))

    def lose(self, error: LinkError | str) -> None:
        """Report the link lost (from any thread); only the first report counts."""
        if isinstance(error, str):
            error = self.link_error(error)
        with self._lock:
            if self.error is not None or self._stop.is_set():
                return
            self.error = error
        self._stop.set()
        LOG.warning('%s', self._about_link(str(error)))
        self._fail_pending(error)

    def _about_link(self, text: str) -> str:
        """``text`` naming the link once (a stream's own errors already name it)."""
        description = self.link.description
        return text if description in text else f'{description}: {text}'

    # --- sending and requests ------------------------------------------------------
    def write(self, data: Any) -> None:
        """Write to the link; a failure is the link's loss (reported, then raised)."""
        if self._stop.is_set():
            raise self._down()
        try:
            self.link.write(data)
        except (LinkError, OSError) as exc:
            error = exc if isinstance(exc, self.link_error) else self.link_error(
                f'{self.link.description}: write failed: {exc}')
            self.lose(error)
            raise error from exc

    @contextmanager
    def expect(self, match: Match) -> Iterator[Pending[Any]]:
        """Register a pending request for the block: what ``match`` accepts from now on
        is queued for it (register before writing, so no answer is missed)."""
        pending = self.register(match)
        try:
            yield pending
        finally:
            self.unregister(pending)

    def register(self, match: Match) -> Pending[Any]:
        """A pending request that outlives one call (a write whose answers are taken
        later): what ``match`` accepts is queued for it until :meth:`unregister`."""
        pending: Pending[Any] = Pending(match)
        with self._lock:
            if self._stop.is_set():
                raise self._down()
            self._pending.append(pending)
        return pending

    def unregister(self, pending: Pending[Any]) -> None:
        with self._lock:
            if pending in self._pending:
                self._pending.remove(pending)

    def request(self, data: Any, match: Match, timeout: float, what: str = 'answer') -> Any:
        """Write ``data`` and return the first message that ``match`` accepts."""
        with self.expect(match) as pending:
            self.write(data)
            return pending.next(timeout, f'{what} from {self.link.description}')

    # --- receiving -------------------------------------------------------------------
    def on(self, kind: type, handler: Callable[[Any], None]) -> None:
        """Call ``handler(message)`` for each dispatched message of type ``kind`` (or of
        a subclass; the most derived registered type wins)."""
        self._handlers[kind] = handler

    def dispatch(self, message: Any) -> None:
        """The handler of the message's type, then every pending request it answers."""
        for kind in type(message).__mro__:
            handler = self._handlers.get(kind)
            if handler is not None:
                try:
                    handler(message)
                except Exception:  # a handler bug must not end the session
                    LOG.exception('%s: error while handling %s', self.name,
                                  type(message).__name__)
                break
        with self._lock:
            pending = list(self._pending)
        for request in pending:
            try:
                request.offer(message)
            except Exception:
                LOG.exception('%s: error while matching %s', self.name, type(message).__name__)

    def _down(self) -> LinkError:
        """A new error saying why the session is down (a fresh instance for each raise:
        re-raising one instance from many threads would grow its traceback)."""
        if self.error is not None:
            return type(self.error)(str(self.error))
        return self.link_error(f'{self.link.description} is not open')

    def _fail_pending(self, error: BaseException) -> None:
        with self._lock:
            pending = list(self._pending)
        for request in pending:
            request.fail(error)

    def _close_link(self) -> None:
        try:
            self.link.close()
        except Exception:  # closing a link that already failed may fail again
            LOG.debug('%s: closing the link failed', self.name, exc_info=True)

    def _run(self) -> None:
        """Read, decode, tick until stopped or the link is lost; then close the link."""
        wake: float | None = None
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                timeout = self.read_timeout if wake is None else \
                    min(self.read_timeout, max(0.0, wake - now))
                try:
                    data = self.link.read(timeout)
                except (LinkError, OSError) as exc:
                    if not self._stop.is_set():
                        self.lose(exc if isinstance(exc, self.link_error) else
                                  self.link_error(self._about_link(str(exc))))
                    break
                if self._stop.is_set():
                    break
                if data:
                    self._guard(self.protocol.data_received, data)
                now = time.monotonic()
                if wake is None or now >= wake:
                    wake = self._guard(self.protocol.tick, now)
        finally:
            self._stop.set()
            self._close_link()
            self._fail_pending(self.error or self.link_error(
                f'{self.link.description}: the session was closed'))
            try:
                self.protocol.connection_lost(self.error)
            except Exception:
                LOG.exception('%s: connection_lost failed', self.name)

    def _guard(self, call: Callable[[Any], Any], argument: Any) -> Any:
        """Run a protocol method: a LinkError it raises is the link's loss, anything else
        is logged (the session goes on)."""
        try:
            return call(argument)
        except LinkError as exc:
            self.lose(exc if isinstance(exc, self.link_error) else self.link_error(str(exc)))
        except Exception:
            LOG.exception('%s: error in %s', self.name, getattr(call, '__name__', call))
        return None
