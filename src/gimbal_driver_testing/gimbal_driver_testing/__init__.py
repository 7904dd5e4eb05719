"""Helpers for tests that start simulators and nodes as separate processes.

Every process gets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a
``ROS_DOMAIN_ID`` leased from a machine-wide pool (a lock file per id), so
concurrent test runs on one machine never see each other's nodes and DDS
never leaves loopback. The pool is ``GIMBAL_TEST_DOMAINS`` (:func:`domain_pool`), so a run
beside a live system keeps off its domain (docs/testing.md, "Beside a live system").
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import ClassVar, TypeVar

from gimbal_driver_common.sim_control import parse_ready_line

T = TypeVar('T')

#: the environment variable that names the test domain pool: ranges ``A-B`` and single ids,
#: comma-separated (``150-229``, ``30,31,40-49``)
DOMAINS_VARIABLE = 'GIMBAL_TEST_DOMAINS'
#: the pool without the variable: none of 0-19, the ids a live system most likely uses
#: (0 is every ROS 2 system's default); none of 110-199, the domains scripts/ros_env.sh gives
#: interactive shells; only ids whose DDS ports lie below or above Linux's ephemeral port
#: range (32768-60999), as the ROS 2 documentation advises (0-101, 215-232)
DEFAULT_DOMAINS = '20-101,215-232'
#: the highest domain Fast DDS accepts (its port formula, 7400 + 250 * domain + offsets,
#: leaves 65535 above 232)
MAX_DOMAIN = 232


def domain_pool(environ: Mapping[str, str] | None = None) -> tuple[int, ...]:
    """The ROS domains tests may lease, from ``GIMBAL_TEST_DOMAINS`` (else
    :data:`DEFAULT_DOMAINS`); raises ValueError naming the variable and what is wrong."""
    raw = (os.environ if environ is None else environ).get(DOMAINS_VARIABLE, '').strip()
    text = raw or DEFAULT_DOMAINS
    pool: list[int] = []
    for item in (part.strip() for part in text.split(',')):
        first, dash, last = item.partition('-')
        try:
            low, high = int(first), int(last if dash else first)
        except ValueError:
            raise ValueError(f'{DOMAINS_VARIABLE}={raw!r}: {item!r} is not a domain id or a '
                             'range A-B (e.g. 150-229 or 30,31,40-49)') from None
        if low > high:
            raise ValueError(f'{DOMAINS_VARIABLE}={raw!r}: the range {item!r} is empty')
        if low < 1 or high > MAX_DOMAIN:
            raise ValueError(f'{DOMAINS_VARIABLE}={raw!r}: {item!r} is outside 1-{MAX_DOMAIN} '
                             f'(Fast DDS accepts 0-{MAX_DOMAIN}; 0 is the default domain of '
                             'every ROS 2 system, never a test domain)')
        pool.extend(domain for domain in range(low, high + 1) if domain not in pool)
    return tuple(pool)


#: every process a ManagedProcess started in this process: the nodes they run are the test's
#: own (gimbal_driver_testing.graph_guard), also after they ended
STARTED_PIDS: set[int] = set()

#: the signal a driver process dumps its threads on (``ros.run.THREAD_DUMP_SIGNAL``; kept
#: here too so that this module stays free of rclpy)
THREAD_DUMP_SIGNAL = signal.SIGUSR2
#: what faulthandler writes at the head of each thread's stack
THREAD_DUMP_MARK = '(most recent call first)'
#: characters of a process' output a failure report shows (the whole log stays on disk)
REPORT_TAIL = 8000
_LOCK_DIR = Path(tempfile.gettempdir()) / 'gimbal-ros-domain-locks'


class DomainLease:
    """Exclusive use of one ROS_DOMAIN_ID while held (flock on a per-id file).

    Successive leases in one process walk round the pool instead of taking
    the first free id again: a domain that a test has just released may
    still hold the discovery traffic of processes it stopped a moment ago,
    and the next test must not see their endpoints (it showed as "more than
    one action server" in an action test that ran right after another).
    """

    _next_offset = 0

    def __init__(self) -> None:
        self.domain_id = -1
        self._file: object | None = None

    def acquire(self) -> int:
        pool = domain_pool()
        _LOCK_DIR.mkdir(exist_ok=True)
        start = (os.getpid() + DomainLease._next_offset) % len(pool)
        for offset in range(len(pool)):
            candidate = pool[(start + offset) % len(pool)]
            handle = open(_LOCK_DIR / f'{candidate}.lock', 'w')  # noqa: SIM115 - held open
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                handle.close()
                continue
            self._file, self.domain_id = handle, candidate
            DomainLease._next_offset += offset + 1
            return candidate
        raise RuntimeError(f'no free ROS_DOMAIN_ID in the test pool {DOMAINS_VARIABLE}='
                           f'{os.environ.get(DOMAINS_VARIABLE, DEFAULT_DOMAINS)!r}')

    def release(self) -> None:
        if self._file is not None:
            self._file.close()  # closing drops the flock
            self._file = None

    def __enter__(self) -> int:
        return self.acquire()

    def __exit__(self, *exc_info: object) -> None:
        self.release()


def ros_env(domain_id: int, extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """This process' environment with DDS confined to loopback and the given domain."""
    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env.pop('ROS_STATIC_PEERS', None)
    env['PYTHONUNBUFFERED'] = '1'
    env['RCUTILS_COLORIZED_OUTPUT'] = '0'
    if extra:
        env.update(extra)
    return env


def find_executable(package: str, executable: str) -> str:
    """Path of ``ros2 run PACKAGE EXECUTABLE`` in the sourced workspace (lib/<pkg>/<exe>)."""
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if not prefix:
            continue
        candidate = Path(prefix, 'lib', package, executable)
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return str(candidate)
    raise FileNotFoundError(
        f'{package}/{executable} not found in AMENT_PREFIX_PATH; build and source the '
        'workspace (make build; source scripts/ros_env.sh)'
    )


def ros_arguments(parameters: Iterable[str]) -> list[str]:
    """Command-line arguments that set a node's ``name:=value`` parameters."""
    return ['--ros-args', *[x for p in parameters for x in ('-p', p)]]


class ManagedProcess:
    """A child process with its output in a log file, stopped like Ctrl-C would.

    The processes of this test process that are still running are in :attr:`live`: when a
    test fails, :mod:`gimbal_driver_testing.node_reports` asks each for a thread dump
    and attaches its log (:meth:`report`); a process that ends a ``with`` block on an
    error does the same before it stops (:meth:`__exit__`). The log file goes when the
    process is stopped (its text stays in :meth:`output`), unless a report named it or
    :attr:`keep_log` is set: a suite of 250 node starts left as many files in the temp
    directory at every run.
    """

    live: ClassVar[dict[int, ManagedProcess]] = {}

    def __init__(
        self, args: Sequence[str], env: Mapping[str, str] | None = None, name: str = ''
    ) -> None:
        self.args = list(args)
        self.name = name or Path(self.args[0]).name
        self._log = tempfile.NamedTemporaryFile(  # noqa: SIM115 - lives as long as the process
            prefix=f'{self.name}-', suffix='.log', delete=False
        )
        self.log_path = self._log.name
        #: keep the log file after :meth:`stop` (a script that names it in its own report)
        self.keep_log = False
        self._reported = False
        self._final_output: str | None = None
        self.process = subprocess.Popen(
            self.args, env=dict(env) if env is not None else None,
            stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        STARTED_PIDS.add(self.process.pid)
        ManagedProcess.live[id(self)] = self

    @classmethod
    def ros(
        cls, package: str, executable: str, domain_id: int, arguments: Sequence[str] = (),
        extra_env: Mapping[str, str] | None = None,
    ) -> ManagedProcess:
        """Start ``ros2 run package executable arguments`` in ``domain_id``."""
        path = find_executable(package, executable)
        return cls([path, *arguments], ros_env(domain_id, extra_env), name=executable)

    @classmethod
    def python(
        cls, module: str, arguments: Sequence[str] = (), domain_id: int | None = None
    ) -> ManagedProcess:
        env = ros_env(domain_id) if domain_id is not None else dict(os.environ)
        return cls([sys.executable, '-m', module, *arguments], env, name=module)

    @property
    def running(self) -> bool:
        return self.process.poll() is None

    def output(self) -> str:
        if self._final_output is not None:
            return self._final_output
        if not self._log.closed:
            self._log.flush()
        return Path(self.log_path).read_text(encoding='utf-8', errors='replace')

    def wait_for_output(self, text: str, timeout: float = 10.0) -> str:
        """Wait until ``text`` appears in the output; return the output."""
        wait_for(lambda: text in self.output() or not self.running, timeout,
                 f'{self.name} to print {text!r}')
        out = self.output()
        if text not in out:
            raise AssertionError(f'{self.name} exited before printing {text!r}:\n{out}')
        return out

    def catches(self, sig: int) -> bool:
        """Whether the process has a handler for ``sig`` (SigCgt in /proc): only then is a
        signal whose default ends a process safe to send."""
        try:
            status = Path(f'/proc/{self.process.pid}/status').read_text()
        except OSError:
            return False
        caught = next((line.split()[1] for line in status.splitlines()
                       if line.startswith('SigCgt:')), '0')
        return bool(int(caught, 16) >> (sig - 1) & 1)

    def thread_dump(self, timeout: float = 5.0) -> bool:
        """Ask a driver process for a dump of its threads (faulthandler, into its log);
        whether one came. False at once for a process without the handler."""
        if not self.running or not self.catches(THREAD_DUMP_SIGNAL):
            return False
        before = self.output().count(THREAD_DUMP_MARK)
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.process.pid, THREAD_DUMP_SIGNAL)
        try:
            wait_for(lambda: self.output().count(THREAD_DUMP_MARK) > before or not self.running,
                     timeout, f'a thread dump of {self.name}')
        except TimeoutError:
            return False
        time.sleep(0.2)  # the handler writes one thread after the other
        return True

    def report(self, tail: int = REPORT_TAIL) -> str:
        """The process' state, where its whole log is kept, and the log's last ``tail``
        characters, for a failure report."""
        state = 'running' if self.running else f'exited {self.process.returncode}'
        self._reported = True
        where = self.log_path if Path(self.log_path).exists() else 'removed at its stop'
        return (f'{self.name} (pid {self.process.pid}, {state}); log: {where}\n'
                f'{self.output()[-tail:]}')

    def send_signal(self, sig: int) -> None:
        if self.running:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.process.pid, sig)

    def stop(self, timeout: float = 10.0) -> int:
        """SIGINT (clean shutdown), then SIGTERM, then SIGKILL; returns the exit code."""
        for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 3.0), (signal.SIGKILL, 3.0)):
            if not self.running:
                break
            self.send_signal(sig)
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.process.wait(wait)
        if self._final_output is None:
            self._final_output = self.output()
            self._log.close()
            if not (self.keep_log or self._reported):
                Path(self.log_path).unlink(missing_ok=True)
        ManagedProcess.live.pop(id(self), None)
        return self.process.returncode if self.process.returncode is not None else -9

    def __enter__(self) -> ManagedProcess:
        return self

    def __exit__(self, exc_type: object, exc: BaseException | None, tb: object) -> None:
        if isinstance(exc, Exception):
            attach_report(exc, self)
        self.stop()


def attach_report(exc: BaseException, process: ManagedProcess) -> None:
    """Add a thread dump (if the process takes one) and the log of ``process`` to ``exc``'s
    notes, so that a failure shows what the process was doing."""
    dumped = process.thread_dump()
    exc.add_note(f'--- {"thread dump and " if dumped else ""}log of '
                 f'{process.report()}')


class ManualClock:
    """A monotonic clock a test sets by hand (``clock.now += 1.0``): pass it where code
    takes ``clock=time.monotonic``."""

    def __init__(self, now: float = 100.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def wait_for(
    condition: Callable[[], T], timeout: float = 10.0, what: str = 'condition',
    interval: float = 0.02,
) -> T:
    """Poll ``condition`` until it returns a truthy value; raise TimeoutError naming ``what``."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f'timed out after {timeout:g} s waiting for {what}')
        time.sleep(interval)


def _ephemeral_port_floor() -> int:
    try:
        return int(Path('/proc/sys/net/ipv4/ip_local_port_range').read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (for a simulator started elsewhere).

    Picked at random *below* the kernel's ephemeral range: a port from ``bind(0)`` is an
    ephemeral one, and the kernel may hand it out again at once as the local port of any
    outgoing connection on the machine (a node connecting to its simulator, another test
    run) before the simulator binds it, which failed the simulator's start at random on a
    busy machine. Below that range only an explicit bind takes a port.
    """
    import random
    import socket

    floor = _ephemeral_port_floor()
    chooser = random.SystemRandom()
    for _ in range(200):
        port = chooser.randrange(10000, floor) if floor > 10001 else 0
        with socket.socket() as sock:
            try:
                sock.bind(('127.0.0.1', port))
            except OSError:
                continue
            return sock.getsockname()[1]
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


def wait_for_ready(process: ManagedProcess, name: str, timeout: float = 30.0) -> dict:
    """Wait for simulator ``name``'s ready line in a process's output; return it (raises if
    the process ends first or the line does not come)."""
    def ready() -> dict | None:
        found = parse_ready_line(process.output(), name)
        if found is None and not process.running:
            raise RuntimeError(f'{name} ended before it was ready:\n{process.output()}')
        return found

    return wait_for(ready, timeout, f'the ready line of {name}')
