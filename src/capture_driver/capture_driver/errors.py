"""The Capture client's errors (no ROS): one hierarchy under
:class:`gimbal_driver_common.errors.GimbalError`, so the controller and the node convert
them at one boundary; each message is meant for a person.
"""

from __future__ import annotations

from gimbal_driver_common import errors, unanswered

from .protocol import (
    REPLY_INFO,
    ReplyCode,
)


class CaptureError(errors.GimbalError):
    """Base of the client's errors; the message is meant for a person."""


class NotConnected(CaptureError, errors.LinkError):
    """No link to the controller (not opened yet, or lost: the supervisor reconnects)."""


class DeviceTimeout(CaptureError, errors.DeviceTimeout):
    """The controller did not answer in time."""


class BackingOff(DeviceTimeout, unanswered.BackingOff):
    """Not sent: a request the host makes on its own went unanswered and waits out its
    back-off (:attr:`CaptureClient.unanswered`)."""


class Preempted(DeviceTimeout, errors.Preempted):
    """Ended before its answer because a stop (or a motion command, for a read) needed the
    link (:meth:`~.answers.AnswerBook.preempt`): nothing of it is retried, its late answer
    is counted by the answer book's rule, never given to another request. Not silence:
    it does not count toward calling the device silent, nor back a poll off."""

    reason = 'preempted by a stop'


class WrongReply(CaptureError, errors.DeviceRefused):
    """The controller answered, but with the other kind of reply: an ACK byte where the
    request takes a data packet, a data packet where it takes an ACK, or data that does not
    decode. A protocol error of that request (the link stays up), never silence."""

    def __init__(self, request: str, answer: str, expected: str) -> None:
        super().__init__(f'{request} answered {answer}, expected {expected}')
        self.request = request
        self.answer = answer
        self.expected = expected


class NotSupported(CaptureError, errors.Unsupported):
    """A request the host makes on its own that the device answered with 0xA6 or the wrong
    kind of reply; it is not sent again on this connection (:attr:`CaptureClient.unsupported`)."""

    def __init__(self, name: str, answer: str) -> None:
        super().__init__(f'{name}: the device does not support it ({answer}); '
                         'not asked again on this connection')
        self.name = name
        self.answer = answer


class DeviceNack(CaptureError, errors.DeviceRefused):
    """The controller answered with a NACK byte; the message carries its meaning."""

    def __init__(self, request: str, code: ReplyCode, detail: str = '',
                 doubt: str = '') -> None:
        info = REPLY_INFO[code]
        message = f'{request}: NACK 0x{int(code):02X} {info.title} ({info.meaning})'
        if doubt:  # the byte names no request: say whose else it may be
            message += f' (not certainly its own: {doubt})'
        if detail:
            message += f'; device says: {detail}'
        if info.advice:
            message += f'; {info.advice}'
        super().__init__(message)
        self.code = code
        self.request = request
        self.detail = detail
        #: why this NACK may be another request's ('' when it is certainly this one's)
        self.doubt = doubt


#: what a request can fail with while the link stays up: a NACK, a reply of the wrong kind,
#: no reply (DeviceTimeout). NotConnected (the link is gone) is not among them.
REQUEST_ERRORS: tuple[type[CaptureError], ...] = (DeviceNack, WrongReply, DeviceTimeout)
