"""The one bridge from Python :mod:`logging` to a node's ROS logger (and so to /rosout).

The ROS-free layers (the core's session, a driver's client, adapter, codec) log with
``logging.getLogger(__name__)``: they know nothing of rclpy. Without a bridge their lines
reach stderr through :data:`logging.lastResort` as bare text (WARNING and above only, no
level, time or node name) and never /rosout. :class:`LogBridge` is a
:class:`logging.Handler` that hands each record to the node's rclpy logger at the same
severity, with the record's logger name in front of the text, so ``rqt_console`` and a bag
of /rosout show it under the node's name.

Which loggers: the *named package loggers* of the code the node runs, not the root logger:
``gimbal_driver_common`` and the driver's own top-level package (plus any names a node
class lists in ``LIBRARY_LOGGERS``). The root logger belongs to whoever runs the process
(pytest's log capture, an application embedding the node): a handler there would also
forward every third-party library's chatter (python-can, hid), whose levels we would have to
lower too to let our INFO lines through. A handler on each package logger sees every record
of that package's modules (records propagate up the dotted names) and leaves propagation
on, so a handler the process put on the root logger still gets them.

Levels: a package logger without a level of its own inherits the root's WARNING, which
would drop the INFO lines (a connect, a reconnect); :meth:`LogBridge.install` sets it to
the node logger's effective level (rcutils' severities are Python's numbers: DEBUG 10 ...
FATAL 50; ``--ros-args --log-level``), and :meth:`LogBridge.remove` puts back what it found.

One bridge per process forwards a record: installing a new one (a second node in the same
process, as the in-process tests make) takes the loggers over from the previous one, and
removing it hands them back. Records come from reader threads: :class:`logging.Handler`
runs :meth:`emit` under its lock, and a thread already inside :meth:`emit` (rcutils or an
output handler that logs through :mod:`logging` again) gets its record printed to stderr
instead of forwarded, so there is no recursion.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterable, Sequence
from typing import Protocol

#: the format of a forwarded line: the library logger's name, then its message
FORMAT = '%(name)s: %(message)s'
#: the core's package logger, bridged for every driver
CORE_LOGGER = 'gimbal_driver_common'


class NodeLogger(Protocol):
    """What the bridge uses of rclpy's ``RcutilsLogger`` (``node.get_logger()``)."""

    name: str

    def get_effective_level(self) -> int: ...

    def debug(self, message: str) -> bool: ...

    def info(self, message: str) -> bool: ...

    def warning(self, message: str) -> bool: ...

    def error(self, message: str) -> bool: ...

    def fatal(self, message: str) -> bool: ...


def bridged_loggers(node_module: str, extra: Iterable[str] = ()) -> list[str]:
    """The package loggers a node of ``node_module`` bridges: the core's, the driver's own
    top-level package, then ``extra``; each once, in that order."""
    names = [CORE_LOGGER, node_module.split('.')[0], *extra]
    return list(dict.fromkeys(name for name in names if name))


class LogBridge(logging.Handler):
    """Forwards the records of some package loggers to one node's ROS logger."""

    #: the bridges installed in this process, oldest first; the last one forwards
    _installed: list[LogBridge] = []
    _registry_lock = threading.Lock()

    def __init__(self, logger: NodeLogger, names: Sequence[str]) -> None:
        super().__init__(logging.NOTSET)
        self.logger = logger
        self.names = list(names)
        self.setFormatter(logging.Formatter(FORMAT))
        self._inside = threading.local()
        #: logger name -> the level it had before this bridge set one (NOTSET: none)
        self._levels: dict[str, int] = {}

    # ------------------------------------------------------------------ install/remove
    def install(self) -> LogBridge:
        """Attach to the package loggers (taking them over from an earlier bridge)."""
        with LogBridge._registry_lock:
            if self in LogBridge._installed:
                return self
            if LogBridge._installed:
                LogBridge._installed[-1]._detach()
            LogBridge._installed.append(self)
            self._attach()
        return self

    def remove(self) -> None:
        """Detach (idempotent); the bridge installed before this one takes over again."""
        with LogBridge._registry_lock:
            if self not in LogBridge._installed:
                return
            current = LogBridge._installed[-1] is self
            LogBridge._installed.remove(self)
            if current:
                self._detach()
                if LogBridge._installed:
                    LogBridge._installed[-1]._attach()

    @property
    def installed(self) -> bool:
        return self in LogBridge._installed

    def _attach(self) -> None:
        level = int(self.logger.get_effective_level()) or logging.INFO
        for name in self.names:
            package = logging.getLogger(name)
            if package.level == logging.NOTSET:
                self._levels[name] = logging.NOTSET
                package.setLevel(level)
            package.addHandler(self)

    def _detach(self) -> None:
        for name in self.names:
            package = logging.getLogger(name)
            package.removeHandler(self)
            if name in self._levels:
                package.setLevel(self._levels.pop(name))

    # ------------------------------------------------------------------ forwarding
    def emit(self, record: logging.LogRecord) -> None:
        if getattr(self._inside, 'active', False):
            if logging.lastResort is not None:  # logged while forwarding: no loop
                logging.lastResort.handle(record)
            return
        self._inside.active = True
        try:
            self._forward(record.levelno, self.format(record))
        except Exception:  # noqa: BLE001 - logging must never raise into the caller
            self.handleError(record)
        finally:
            self._inside.active = False

    def _forward(self, level: int, text: str) -> None:
        # One call site per severity: rclpy keys a call's filter context by its caller
        # (file, line, instruction) and raises "Logger severity cannot be changed between
        # calls" when one site logs at two severities (rclpy impl/rcutils_logger.py,
        # RcutilsLogger.log).
        if level >= logging.CRITICAL:
            self.logger.fatal(text)
        elif level >= logging.ERROR:
            self.logger.error(text)
        elif level >= logging.WARNING:
            self.logger.warning(text)
        elif level >= logging.INFO:
            self.logger.info(text)
        else:
            self.logger.debug(text)


def install_log_bridge(logger: NodeLogger, node_module: str,
                       extra: Iterable[str] = ()) -> LogBridge:
    """Bridge the core's and the driver's package loggers to ``logger`` (a node's)."""
    return LogBridge(logger, bridged_loggers(node_module, extra)).install()
