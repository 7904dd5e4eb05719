"""The Capture motion set-ups (no ROS): the 7.1 motion profile, speed mode, stops and the
stream move written without waiting for its ACKs. A part of :class:`~.client.CaptureClient`,
handed the link (:class:`~.link.CaptureLink`), its set-up memory (:class:`~.link.AxisSetups`),
the polls (``run``, what the device does not know) and the batch part (whether stream
moves may be posted, and their count).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from gimbal_driver_common.errors import DeviceRefused
from gimbal_driver_common.transport import ByteStream

from .answers import Waiting
from .batch import BatchedReads
from .device_requests import Polls
from .errors import (
    CaptureError,
    DeviceNack,
    DeviceTimeout,
    NotConnected,
    Preempted,
)
from .link import AxisSetups, CaptureLink, answer_time
from .protocol import (
    Frame,
    ProtocolError,
    ReplyByte,
    ReplyCode,
    command,
)

LOG = logging.getLogger('capture_driver.motion')

#: motion set-up steps the protocol calls advisory (4.2.14 "it is advisable to send this
#: command before each command session", 7.1 "MOT_SetTum (as needed)"): a controller that
#: does not know one (0xA6 while the rest of the set-up is accepted) is driven without it
ADVISORY_STEPS = frozenset({'MOT_SetTum'})


@dataclass
class PostedMoves:
    """A stream move written by :meth:`MotionRequests.post_moves`: per axis
    ``(position_deg, speed_deg_s, acceleration)``, the frames in order (one ACK each,
    waiting for it in the link's answer book) and the stream they went out on. The core
    carries it (``PostedWrite.expected``) until :meth:`MotionRequests.settle_posted` takes
    the ACKs."""

    moves: dict[int, tuple[float, float, float]]
    waitings: list[Waiting]
    stream: ByteStream


#: one axis' stop (speed mode, speed 0, update); see :meth:`MotionRequests.stop_axes`
AXIS_STOP: tuple[tuple[str, Any], ...] = (('MOT_SetSpeedMode', None), ('MOT_SetSpeed', 0.0),
                                          ('MOT_Update', None))
#: the device programs a stop of everything ends, after the axes, the scan last (4.3.9)
PROGRAM_STOPS = ('PRST_StopPresetLooping', 'GPS_StopTargetLooping', 'SCN_StopScan')


@dataclass
class StopAnswers:
    """What the device answered to a stop: the axis steps' problems (``errors``) and the
    program stops' (``programs``, by name: a refusal there is the caller's to judge)."""

    steps: int
    errors: list[CaptureError | DeviceRefused] = field(default_factory=list)
    programs: dict[str, CaptureError] = field(default_factory=dict)


class MotionRequests:
    """Motion set-ups of :class:`~.client.CaptureClient`."""

    def __init__(self, link: CaptureLink, setups: AxisSetups, polls: Polls,
                 batch: BatchedReads) -> None:
        self._link = link
        self._setups = setups
        self._polls = polls
        self._batch = batch

    def move_absolute(self, axis: int, position_deg: float, speed_deg_s: float,
                      acceleration: float) -> None:
        """The 7.1 motion profile, absolute: mode, TUM, absolute, acc, speed, position, update.

        When this client's last set-up of the axis was an absolute move and nothing else was
        commanded since, the mode commands (SetPositionMode, SetPositionAbsolute) and an
        unchanged acceleration and speed are left out. 4.2.14: without TUM "the motion
        profile will use the last parameters", and TUM builds the new profile from the
        acceleration, speed and position registers, so an unchanged register need not be
        written again.

        TUM is sent before every session ("advisable before each command session", 4.2.14),
        but for a stream of moves it is sent for the *next* session right after this one's
        MOT_Update: the 7.1 sequence already puts register writes between TUM and
        MOT_Update, and only reads (the poll) come between them here. A stream at one speed
        then costs SendPosition and MOT_Update before the device acts, and TUM after it:
        the same 3 transactions, one less round trip on the way to MOT_Update. Anything else
        commanded on the link forgets the armed TUM, and the next move sends it first again.
        """
        speed = abs(speed_deg_s)
        with self._link.link_lock, self._link.answers.motion_first():
            known = self._setups.known.pop(axis, None)
            if known is not None and known[0] != 'absolute':
                known = None  # another mode: the whole set-up goes out
            steps: list[tuple[str, Any]] = []
            if known is None:
                steps.append(('MOT_SetPositionMode', None))
            if known is None or not known[3]:  # no TUM armed for this session
                steps.append(('MOT_SetTum', None))
            if known is None:
                steps.append(('MOT_SetPositionAbsolute', None))
            if known is None or known[1] != acceleration:
                steps.append(('MOT_SetAcceleration', acceleration))
            if known is None or known[2] != speed:
                steps.append(('MOT_SetSpeed', speed))
            steps += [('MOT_SendPosition', position_deg), ('MOT_Update', None)]
            self._run_setup(axis, steps)
            self._setups.known[axis] = ('absolute', acceleration, speed, self._arm_tum(axis))

    def _arm_tum(self, axis: int) -> bool:
        """MOT_SetTum for the axis' next session (see :meth:`move_absolute`); False when it
        failed, so that session sends it itself (and judges an 0xA6 with the rest of its
        set-up), or when the device does not know it. The move already happened: a failure
        here is not the move's."""
        if 'MOT_SetTum' in self._link.unsupported:
            return False
        self._setups.in_setup = True
        try:
            self._link.request('MOT_SetTum', axis)
        except CaptureError as exc:
            LOG.debug('TUM for the next move of axis %d: %s', axis, exc)
            return False
        finally:
            self._setups.in_setup = False
        return True

    def post_moves(self, moves: dict[int, tuple[float, float, float]]) -> PostedMoves | None:
        """Write a stream move at once, without waiting for any reply: what was written, or
        None with nothing written.

        ``moves``: axis -> (position_deg, speed_deg_s, acceleration). Only the common case
        of a command stream is posted: every axis already set up by this client for
        absolute moves at this speed and acceleration, with a TUM armed (see
        :meth:`move_absolute`), so the move is MOT_SendPosition + MOT_Update per axis. They
        go out in one write, as :meth:`read_many` writes its getters (the same reading of
        the document: the controller answers requests in the order they came; and the
        same way back: :attr:`batching` off means one request at a time). None when the
        link is down or the move needs more than that; the caller then sends it with
        :meth:`move_absolute`.

        The caller holds the link lock (the command path's one try, from the
        joint_command callback). The lock settles the post before the link's next
        exchange (``gimbal_driver_common.link_lock``): :meth:`settle_posted` reads the ACKs
        and arms the next TUM. A NACK to SendPosition leaves the MOT_Update that follows it
        to re-run the previous profile: the target the axis already has.
        """
        with self._link.link_lock:  # reentrant: the caller's hold
            stream = self._link.stream
            if stream is None or not self._batch.batching:
                return None
            if any(self._setups.known.get(axis) != ('absolute', acceleration, abs(speed), True)
                   for axis, (_, speed, acceleration) in moves.items()):
                return None
            try:
                frames = [(name, command(name).frame(axis, value, self._link.group), False)
                          for axis, (position, _, _) in moves.items()
                          for name, value in (('MOT_SendPosition', position),
                                              ('MOT_Update', None))]
            except ProtocolError:
                return None  # move_absolute raises it, with nothing sent
            # the caller never waits: when a read the device may answer with a byte is in
            # flight, the command thread sends the move instead
            waitings = self._link.write(frames, block=False)
            if waitings is None:
                return None
            for axis, (_, speed, acceleration) in moves.items():
                self._setups.known[axis] = ('absolute', acceleration, abs(speed), False)
            self._link.count('posted_moves')
            return PostedMoves(dict(moves), waitings, stream)

    def settle_posted(self, posted: PostedMoves) -> bool:
        """Take the ACKs of a :meth:`post_moves`, in order, and arm the next TUM; raises the
        device's refusal, or :class:`NotConnected` when the link closed before they came.
        False: an ACK was lost (or a NACK says the packet was not executed, 0xF6), so the
        caller sends the moves again with :meth:`move_absolute` (the axes' set-up is
        forgotten: the whole 7.1 sequence goes out). Run under the link lock before its
        next setter. Under a stop's hold (:meth:`LinkLock.urgent`) it writes nothing: a
        preempted post counts as written, and no TUM is armed (the next move sends it)."""
        with self._link.link_lock:
            if self._link.stream is not posted.stream:
                for axis in posted.moves:
                    self._setups.known.pop(axis, None)
                raise NotConnected(f'stream move: link closed before its ACKs came '
                                   f'({self._link.last_error})')
            try:
                error, resend = self._posted_answers(posted)
            except Preempted:
                # a stop cut its answers short: they are the stop's to count, and the move
                # was written; the next move sends the whole set-up again
                for axis in posted.moves:
                    self._setups.known.pop(axis, None)
                return True
            if error is not None or resend:
                for axis in posted.moves:
                    self._setups.known.pop(axis, None)
            if error is not None and not resend:
                raise error
            if resend:
                return False
            if self._link.link_lock.held_urgently():
                return True  # a stop's hold writes nothing before the stop: no TUM now
            for axis, (_, speed, acceleration) in posted.moves.items():
                if self._setups.known.get(axis) == ('absolute', acceleration, abs(speed), False):
                    self._setups.known[axis] = ('absolute', acceleration, abs(speed),
                                                self._arm_tum(axis))
            return True

    def _posted_answers(self, posted: PostedMoves) -> tuple[CaptureError | None, bool]:
        """The ACK of each posted frame, in order: the first refusal (or the link lost) and
        whether to send the moves again (an ACK missing, or 0xF6)."""
        link = self._link
        deadline = posted.waitings[0].written_at + link.timeout
        try:
            answers = [link.answer(waiting, deadline) for waiting in posted.waitings]
        except NotConnected as exc:
            return exc, False
        error: CaptureError | None = None
        resend = False
        for waiting, answer in zip(posted.waitings, answers, strict=True):
            if isinstance(answer, ReplyByte) and not answer.is_ack and error is None:
                error = DeviceNack(link.label(waiting.name, waiting.frame), answer.code,
                                   doubt=waiting.doubt)
                resend = answer.code == ReplyCode.WRONG_CHECKSUM
            elif isinstance(answer, Frame) and error is None:  # data where an ACK belongs
                error = link.wrong_reply(waiting.name, waiting.frame, 'data', 'ACK')
        complete = all(answer is not None for answer in answers)
        self._batch.count_batch(complete=complete)
        if complete:
            return error, resend
        if all(answer is None for answer in answers):
            link.count_timeout('stream move')
        return error, True

    def jog(self, axis: int, velocity_deg_s: float, acceleration: float) -> None:
        """Speed mode (4.2.9): the axis turns at ``velocity_deg_s`` until told otherwise.

        Speed mode and an unchanged acceleration are left out when this client's last
        set-up of the axis left it in speed mode (a jog or a stop) and nothing else was
        commanded since: a stream of jog commands costs 2 round trips each, not 4.

        A sensor read the device has not answered yet does not hold it up: for the set-up
        it is taken as answered by data or nothing (:meth:`~.answers.AnswerBook.motion_first`),
        as for a move's.
        """
        with self._link.link_lock, self._link.answers.motion_first():
            known = self._setups.known.pop(axis, None)
            if known is not None and known[0] != 'speed':
                known = None  # another mode: the whole set-up goes out
            steps: list[tuple[str, Any]] = []
            if known is None:
                steps.append(('MOT_SetSpeedMode', None))
            if known is None or known[1] != acceleration:
                steps.append(('MOT_SetAcceleration', acceleration))
            steps += [('MOT_SetSpeed', velocity_deg_s), ('MOT_Update', None)]
            self._run_setup(axis, steps)
            self._setups.known[axis] = ('speed', acceleration, velocity_deg_s, False)

    def stop_axis(self, axis: int) -> None:
        """:meth:`stop_axes` of one axis; raises its first problem."""
        answers = self.stop_axes([axis])
        if answers.errors:
            raise answers.errors[0]

    def stop_axes(self, axes: Sequence[int], programs: bool = False) -> StopAnswers:
        """Decelerate ``axes`` to rest, and with ``programs`` end the device's preset loop,
        target loop and scan: every step written at once, then the answers read.

        Per axis speed mode with speed 0 (works from position or speed mode): MOT_SetSpeedMode,
        MOT_SetSpeed 0, MOT_Update, always the whole sequence (a stop never relies on what
        the client remembers). Then PRST_StopPresetLooping, GPS_StopTargetLooping and last
        SCN_StopScan: the axes' motion goes first, and nothing waits behind the scan stop,
        which the controller may take 500 ms to answer before it handles anything new
        (4.3.9). While it scans the controller may refuse the motor steps with 0xA6 (4.3);
        SCN_StopScan "stops both motors immediately", so such a refusal is no failure when
        the scan stop is ACKed. One write, one exchange of the answer book: no step waits
        for the answer of another, and a step that fails skips nothing. (On a controller
        found to drop queued requests, :attr:`~.batch.BatchedReads.batching` off, the
        steps go one at a time, each after the answer or timeout of the one before: it
        would drop the rest of one write; still none is skipped.) Each answer waits
        its own time (the request timeout; SCN_StopScan its 500 ms plus
        :data:`~.link.ANSWER_MARGIN_S`). Whether the axes came to rest is the core's to
        confirm from the joint samples; these answers say only what the device said. An
        axis is remembered in speed mode (the next jog leaves MOT_SetSpeedMode out) only
        when each of its steps is known ACKed: one refused while a scan ran (0xA6), or
        answered only as a whole, gets the whole set-up again.
        """
        link = self._link
        with link.link_lock:
            for axis in axes:
                self._setups.known.pop(axis, None)
            requests = [(name, command(name).frame(axis, value, link.group), False)
                        for axis in axes for name, value in AXIS_STOP]
            if programs:
                requests += [(name, command(name).frame(None, None, link.group), False)
                             for name in PROGRAM_STOPS]
            if self._batch.batching:
                waitings = link.write(requests, urgent=True) or []  # a stop waits for nothing
                answers = [link.answer(w, self._deadline(w)) for w in waitings]
            else:  # a controller that drops queued requests: one step at a time, none skipped
                waitings, answers = [], []
                for request in requests:
                    [waiting] = link.write([request], urgent=True) or []
                    waitings.append(waiting)
                    answers.append(link.answer(waiting, self._deadline(waiting)))
            exchange = waitings[0].exchange if waitings else None
            for axis in axes:  # in speed mode only where each step is known ACKed
                steps = [a for w, a in zip(waitings, answers, strict=True)
                         if w.frame.axis == axis and w.name in dict(AXIS_STOP)]
                if not (exchange is not None and exchange.whole) and len(steps) == len(
                        AXIS_STOP) and all(isinstance(a, ReplyByte) and a.is_ack
                                           for a in steps):
                    self._setups.known[axis] = ('speed', None, 0.0, False)
        result = StopAnswers(len(waitings))
        if all(answer is None for answer in answers) and waitings:
            link.count_timeout('stop')
        if exchange is not None and exchange.whole:
            self._judge_whole(result, exchange.received, exchange.doubt, waitings)
        else:
            self._judge_each(result, waitings, answers)
        return result

    def _deadline(self, waiting: Waiting) -> float:
        return self._link.deadline(waiting, max(self._link.timeout, answer_time(waiting.name)))

    def _judge_each(self, result: StopAnswers, waitings: list[Waiting],
                    answers: list[Frame | ReplyByte | None]) -> None:
        """Answers the book gave one by one: each step's own."""
        link = self._link
        scan = next((a for w, a in zip(waitings, answers, strict=True)
                     if w.name == 'SCN_StopScan'), None)
        scan_stopped = isinstance(scan, ReplyByte) and scan.is_ack
        for waiting, answer in zip(waitings, answers, strict=True):
            label = link.label(waiting.name, waiting.frame)
            error: CaptureError | None = None
            if isinstance(answer, ReplyByte) and not answer.is_ack:
                if scan_stopped and waiting.frame.axis and (
                        answer.code == ReplyCode.INVALID_COMMAND):
                    continue  # refused while scanning; the scan stop stopped the motors
                error = DeviceNack(label, answer.code, doubt=waiting.doubt)
            elif isinstance(answer, Frame):
                error = link.wrong_reply(waiting.name, waiting.frame, 'data', 'ACK')
            elif answer is None:
                error = DeviceTimeout(f'{label}: no reply within '
                                      f'{max(link.timeout, answer_time(waiting.name)):g} s')
            if error is None:
                continue
            if waiting.frame.axis:
                result.errors.append(error)
            else:
                result.programs[waiting.name] = error

    @staticmethod
    def _judge_whole(result: StopAnswers, received: list[ReplyByte], doubt: str,
                     waitings: list[Waiting]) -> None:
        """Bytes the stop's batch owns as a whole (it went out while other answers could
        still come): only what they say together is known."""
        names = ', '.join(dict.fromkeys(w.name for w in waitings))
        nacks = sorted({f'0x{int(b.code):02X}' for b in received if not b.is_ack})
        if nacks:
            result.errors.append(DeviceRefused(
                f'stop ({names}): NACK {", ".join(nacks)} among its {len(waitings)} '
                f'answers, which name no request ({doubt})'))
        if len(received) < len(waitings):
            result.errors.append(DeviceTimeout(
                f'stop ({names}): {len(received)} of {len(waitings)} answers came ({doubt})'))

    def _run_setup(self, axis: int, steps: list[tuple[str, Any]]) -> None:
        """Send one axis' motion set-up under the lock; the setters in it do not count as
        "something else commanded" (see :attr:`_setups`).

        An advisory step (:data:`ADVISORY_STEPS`: MOT_SetTum) refused with 0xA6 does not
        end the set-up. When the device accepts the rest, it does not know the step: it is
        recorded in :attr:`unsupported` (said once) and left out of later set-ups on this
        connection. When the rest is refused too, the 0xA6 meant the mode (scanning,
        stabilising, ...), and the set-up fails with the later refusal as before.
        """
        refused: tuple[str, DeviceNack] | None = None
        self._setups.in_setup = True
        try:
            for name, value in steps:
                if name not in ADVISORY_STEPS:
                    self._polls.run(name, axis, value)
                elif name not in self._link.unsupported:
                    try:
                        self._polls.run(name, axis, value)
                    except DeviceNack as exc:
                        if exc.code != ReplyCode.INVALID_COMMAND:
                            raise
                        refused = (name, exc)
        finally:
            self._setups.in_setup = False
        if refused is not None:
            name, nack = refused
            answer = f'0x{command(name).opcode:04X} answered NACK 0xA6'
            self._polls.not_supported(name,
                                      f'{answer} "{nack.detail}"' if nack.detail else answer)
            self._polls.clear_own_protocol_error()
