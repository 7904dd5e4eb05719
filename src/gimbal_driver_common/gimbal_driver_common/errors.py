"""One error hierarchy for every driver, and the boundary that converts foreign errors into it.

Clients raise these (their own exception classes subclass them), the controller
turns anything else that escapes a device call into one with :func:`device_boundary`,
and the ROS node answers ``success=false`` with ``str(error)``. Modelled on
python-can's ``can/exceptions.py``: the class says what happened, the message
carries the device's own reason.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager


class GimbalError(Exception):
    """Anything a device request or a command can fail with; the message is for people.

    ``reason`` is a short name of what went wrong that does not change with the values in
    the message ("pan: position outside the limits", "node not active"): what the
    diagnostics count refused commands by and what their log lines are throttled by. The
    class gives a default; ``reason=`` names it more precisely.
    """

    reason = 'device error'

    def __init__(self, *args: object, reason: str = '') -> None:
        super().__init__(*args)
        if reason:
            self.reason = reason


class LinkError(GimbalError):
    """The link is down or dropped during the request (the supervisor reconnects)."""

    reason = 'link lost'


class DeviceTimeout(GimbalError, TimeoutError):
    """The device did not answer in time."""

    reason = 'no answer from the device'


class Preempted(DeviceTimeout):
    """Ended before its answer because a stop needed the link at once
    (``LinkLock.preempt``): not the device's silence. The command path sends a preempted
    move or jog again after the stop, once, where the stop did not cover its joints
    (:class:`~gimbal_driver_common.command_path.CommandPath`)."""

    reason = 'preempted by a stop'


class DeviceRefused(GimbalError):
    """The device, or the driver on its behalf, refused: NACK, off/faulted axis, busy."""

    reason = 'refused by the device'


class Unsupported(DeviceRefused):
    """The device (or this driver for it) does not know the command."""

    reason = 'not supported by the device'


class InvalidRequest(GimbalError, ValueError):
    """The request itself is wrong (out of range, unknown joint); nothing was sent."""

    reason = 'invalid request'


#: exceptions that mean "the link is gone" (pyserial's SerialException is an OSError;
#: python-can's errors are converted by the turret's client, so this package needs no can)
_LINK_TYPES: tuple[type[BaseException], ...] = (OSError, EOFError)


def as_gimbal_error(exc: BaseException) -> GimbalError:
    """The :class:`GimbalError` that ``exc`` means (itself when it already is one)."""
    if isinstance(exc, GimbalError):
        return exc
    if isinstance(exc, TimeoutError):
        error: GimbalError = DeviceTimeout(str(exc) or 'no answer from the device')
    elif isinstance(exc, _LINK_TYPES):
        error = LinkError(f'link: {exc}')
    elif isinstance(exc, ValueError):
        error = InvalidRequest(str(exc))
    else:
        error = GimbalError(f'{type(exc).__name__}: {exc}')
    error.__cause__ = exc
    return error


@contextmanager
def device_boundary() -> Iterator[None]:
    """Re-raise whatever escapes the block as a :class:`GimbalError` (the one conversion point)."""
    try:
        yield
    except GimbalError:
        raise
    except Exception as exc:
        raise as_gimbal_error(exc) from exc


class EverySteps:
    """The steps of a stop: each is tried whatever the one before did (an error or a
    timeout skips no other step); :meth:`raise_errors` then raises every failure at once.
    ``with EverySteps() as steps: steps.run(...)`` raises on leaving the block."""

    def __init__(self) -> None:
        self.errors: list[GimbalError] = []

    def run(self, request: Callable[..., object], *args: object) -> None:
        try:
            request(*args)
        except Exception as exc:  # noqa: BLE001 - collected, raised after every step
            self.errors.append(as_gimbal_error(exc))

    def raise_errors(self) -> None:
        """Raise the one failure, or one GimbalError naming them all (the first's reason)."""
        if len(self.errors) == 1:
            raise self.errors[0]
        if self.errors:
            raise GimbalError('; '.join(map(str, self.errors)),
                              reason=self.errors[0].reason) from self.errors[0]

    def __enter__(self) -> EverySteps:
        return self

    def __exit__(self, kind: object, exc: object, traceback: object) -> None:
        if kind is None:
            self.raise_errors()
