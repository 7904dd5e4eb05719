"""Batched reads of the Capture client (no ROS): several getters in one write, their
replies matched by opcode and axis, and the way back to one request at a time when a
controller drops what it queues. A part of :class:`~.client.CaptureClient`, handed the
link (:class:`~.link.CaptureLink`) and the polls (:class:`~.device_requests.Polls`) it uses.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

from .answer_records import Waiting
from .device_requests import Polls, request_key
from .errors import DeviceTimeout, NotSupported, WrongReply
from .link import CaptureLink
from .protocol import Command, Frame, ProtocolError, ReplyByte, command

LOG = logging.getLogger('capture_driver.batch')

#: batched reads in a row that came back incomplete before :meth:`CaptureClient.read_many`
#: falls back to one request at a time for the connection
BATCH_FAILURES = 3


@dataclass(eq=False)
class AskedBatch:
    """A batch :meth:`BatchedReads.ask_many` wrote and has not handed on yet."""

    frames: list[tuple[Command, int | None, Frame]]
    on_values: Callable[[list[Any]], object]
    waitings: list[Waiting] = field(default_factory=list)
    #: when its last getter gives up (monotonic s); until then its answers may come
    deadline: float = float('inf')
    #: its answers, when each came but not all as plain data (settled by the asker)
    answers: list[Frame | ReplyByte | None] | None = None

    def due(self) -> bool:
        return time.monotonic() >= self.deadline


class BatchedReads:
    """:meth:`read_many` of :class:`~.client.CaptureClient`, and whether it batches on this
    connection (:attr:`batching`; back to :attr:`batch_reads` on every connect)."""

    def __init__(self, link: CaptureLink, polls: Polls, batch_reads: bool = True) -> None:
        self._link = link
        self._polls = polls
        #: getters of :meth:`read_many` go out in one write (False: one at a time)
        self.batch_reads = batch_reads
        self.batching = batch_reads
        self._failures = 0
        self._last_frames: tuple[object, list[tuple[Command, int | None, Frame]]] = (
            None, [])
        #: the batch :meth:`ask_many` wrote, until its values are handed on
        self._asked: AskedBatch | None = None
        self._asked_lock = threading.Lock()
        link.connect_hooks.append(self._new_connection)

    def _new_connection(self) -> None:
        self.batching, self._failures = self.batch_reads, 0
        with self._asked_lock:
            self._asked = None  # the old link's: it answers nothing any more

    def read_many(self, reads: Sequence[tuple[str, int | None]],
                  optional: bool = False) -> list[Any]:
        """Several getters (``(name, axis)``) written at once, their replies matched by
        opcode and axis; returns the decoded values in order.

        ``optional``: reads the host makes on its own (the status registers), each as
        :meth:`poll`: None for a getter the device does not answer with data (it is not
        sent again), so the rest are read from what the device does report.

        A data reply names the opcode and axis it answers (section 3), so getters need not
        wait for each other: the joint poll (position and speed of each axis) costs one
        round trip instead of four, and holds the link for that long only. The protocol
        document shows one request at a time and says nothing of queuing, so this is our
        reading of it, with a way back: a batch that gets a NACK or misses a reply has
        the missing reads sent again one at a time (with :meth:`request`'s retry rules),
        and after ``BATCH_FAILURES`` such batches in a row the client reads one at a
        time for the rest of the connection (:attr:`batching` says which, in diagnostics).
        An ACK byte names neither opcode nor axis: in a batch it only says that one of the
        reads got no data, and that read is then named by asking it alone.
        """
        frames = self._frames(reads)
        link = self._link
        with contextlib.ExitStack() as held:
            held_lock = not link.overlap
            if held_lock:
                held.enter_context(link.link_lock)
            asked = [i for i, (cmd, axis, _) in enumerate(frames)
                     if not (optional and self._left_out(cmd.name, axis))]
            answers: list[Frame | ReplyByte | None] = [None] * len(asked)
            batched = self.batching and len(asked) >= 2
            if batched:
                waitings = link.write([(frames[i][0].name, frames[i][2], True)
                                       for i in asked]) or []
                answers = self._collect(waitings)
                if not link.overlap and not held_lock:  # this batch ended the overlap:
                    held.enter_context(link.link_lock)  # its reads alone go one at a time
            return self._values(frames, asked, answers, batched, optional)

    @property
    def asked(self) -> AskedBatch | None:
        """The batch :meth:`ask_many` wrote and has not handed on (diagnostics, tests)."""
        with self._asked_lock:
            return self._asked

    def ask_many(self, reads: Sequence[tuple[str, int | None]],
                 on_values: Callable[[list[Any]], object]) -> bool:
        """:meth:`read_many` (not optional) without waiting: the getters written now, and
        ``on_values(values)`` called by the reader thread once each has its data (the
        caller's thread wakes once a poll, for the write, not again for the answer).
        True: asked, or an earlier ask still waits for its answers; False: ask with
        :meth:`read_many` (not batching, not overlapping, or a getter not known to answer
        with data yet: its answer could be a byte). Whatever is not plain data (a NACK,
        an ACK, data that does not decode) or does not come by its deadline is settled
        here, at the next call, with :meth:`read_many`'s rules (asked again alone, the
        timeout counted), and ``on_values`` called from this thread; raises as
        :meth:`read_many` does."""
        link = self._link
        with self._asked_lock:
            asked, self._asked = self._asked, None
            if asked is not None and asked.answers is None and not asked.due():
                self._asked = asked
                return True  # its answers may still come
        if asked is not None:  # answered but not plainly, or past its deadline
            if asked.answers is not None:
                answers = asked.answers
                self.count_batch(complete=True)  # each answered, a byte too: as _collect
            else:
                answers = self._collect(asked.waitings)
            with contextlib.ExitStack() as held:
                if not link.overlap:
                    held.enter_context(link.link_lock)
                on_values(self._values(asked.frames, list(range(len(asked.frames))),
                                       answers, True, False))
            return True
        frames = self._frames(reads)
        if not (self.batching and link.overlap and len(frames) >= 2
                and link.answers.answer_with_data([frame for _, _, frame in frames])):
            return False
        ask = AskedBatch(frames, on_values)
        with self._asked_lock:
            self._asked = ask
        try:
            waitings = link.write([(cmd.name, frame, True) for cmd, _, frame in frames],
                                  on_answered=partial(self._answered, ask))
        except BaseException:
            with self._asked_lock:
                self._asked = None
            raise
        ask.waitings = waitings or []
        ask.deadline = max(link.deadline(w, link.timeout) for w in ask.waitings)
        return True

    def _answered(self, ask: AskedBatch, waitings: list[Waiting]) -> None:
        """Every getter of ``ask`` has its answer (on the reader thread): plain data is
        handed on here; anything else is left to :meth:`ask_many`'s next call."""
        with self._asked_lock:
            if self._asked is not ask:
                return  # settled by the asking thread already
            answers = self._link.answers.take(waitings)
            values: list[Any] = []
            for (cmd, _, frame), answer in zip(ask.frames, answers, strict=True):
                if not isinstance(answer, Frame):
                    break
                try:
                    values.append(self._link.decode(cmd.name, frame, answer))
                except WrongReply:
                    break
            if len(values) < len(ask.frames):
                ask.answers = answers
                return
            self._asked = None
        self.count_batch(complete=True)
        ask.on_values(values)

    def _frames(self, reads: Sequence[tuple[str, int | None]]
                ) -> list[tuple[Command, int | None, Frame]]:
        """Each read's command, axis and frame; the frames of the last reads asked are
        kept (frames are immutable: the joint poll asks the same four at every tick)."""
        key = (tuple(reads), self._link.group)
        last = self._last_frames  # one read: other threads ask other reads
        if last[0] == key:
            return last[1]
        frames = []
        for name, axis in reads:
            cmd = command(name)
            if not cmd.replies_with_data:
                raise ProtocolError(f'{name} is not a getter: only getters are batched')
            frames.append((cmd, axis, cmd.frame(axis, None, self._link.group)))
        self._last_frames = (key, frames)
        return frames

    def _values(self, frames: list[tuple[Command, int | None, Frame]], asked: list[int],
                answers: list[Frame | ReplyByte | None], batched: bool,
                optional: bool) -> list[Any]:
        """The values of a batch's answers; a read not answered with data is asked again
        alone (optional ones by :meth:`Polls.poll`'s rules)."""
        link = self._link
        values: list[Any] = [None] * len(frames)
        # only the first read answered: what a controller that drops queued requests
        # does, not one silent read (with two reads the two look alike)
        dropped_queue = (batched and answers[0] is not None
                         and all(answer is None for answer in answers[1:]))
        for i, answer in zip(asked, answers, strict=True):
            cmd, axis, frame = frames[i]
            if isinstance(answer, Frame):
                with contextlib.suppress(WrongReply):  # undecodable: asked alone below
                    values[i] = link.decode(cmd.name, frame, answer)
                    if optional:
                        self._polls.answered(cmd.name, axis)
                    continue
            if optional and batched and answer is None and answers.count(None) == 1 and (
                    not dropped_queue):
                # the one read of the batch with nothing at all while the device answered
                # the rest: silent, not ambiguous (a controller that drops what it queues
                # loses every read after the first); asked again after its back-off, not
                # at once alone
                self._polls.went_unanswered(cmd.name, axis)
                continue
            # NACKed, answered without data or unanswered: once more, on its own
            if not optional:
                values[i] = link.request_locked(cmd.name, axis, None)
                continue
            # None: not asked again (unsupported), or not now (unanswered: back-off)
            with contextlib.suppress(NotSupported, DeviceTimeout):
                values[i] = self._polls.poll(cmd.name, axis)
        return values

    def _left_out(self, name: str, axis: int | None) -> bool:
        """An optional read not to send now: the device does not know it, or it went
        unanswered and waits out its back-off (see :meth:`Polls.poll`)."""
        return (name in self._link.unsupported
                or self._link.unanswered.waiting(request_key(name, axis)) is not None)

    def _collect(self, waitings: list[Waiting]) -> list[Frame | ReplyByte | None]:
        """The answer to each of a batch's getters within :attr:`timeout`: its data, a
        reply byte (a NACK or an ACK went to it: which read it belongs to, the byte does
        not say, so a read that got one is asked alone), or None (nothing)."""
        link = self._link
        answers = [link.answer(waiting, link.deadline(waiting, link.timeout))
                   for waiting in waitings]
        if len(answers) >= 2 and answers[0] is not None and all(
                answer is None for answer in answers[1:]):
            # only the first answered: the rest were dropped unread (a controller that
            # drops what it queues), not answered late, so asking them again waits for
            # no late answer (see answers.py)
            link.answers.dropped(waitings[1:])
        if all(answer is None for answer in answers):  # not one answer: a timeout
            link.count_timeout('batched read')
        # each read answered (a NACK or ACK too): the controller handles queued requests
        self.count_batch(complete=all(answer is not None for answer in answers))
        return answers

    def count_batch(self, complete: bool) -> None:
        """One batch (the poll's getters, or a posted stream move) came back whole or not.
        ``BATCH_FAILURES`` incomplete ones in a
        row end batching for the connection (one request at a time)."""
        if complete:
            self._failures = 0
            return
        self._link.count('incomplete_batches')
        self._failures += 1
        if self._failures >= BATCH_FAILURES:
            self.batching = False
            self._link.overlap = False  # nor do requests overlap: one at a time
            LOG.info('%d batches in a row came back incomplete: one request at a time on '
                     'this connection', self._failures)
