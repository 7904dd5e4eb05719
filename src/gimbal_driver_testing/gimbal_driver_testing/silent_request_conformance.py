"""The silent-request part of the conformance suite: one kind of request the device never
answers (the simulators' ``mute REQUEST``), or answers late (``delay REQUEST SECONDS``),
costs only itself, through the real transport, client and node.

Each driver's suite names its requests by kind (:attr:`SilentRequestConformance.silent_requests`:
a sensor getter, a status register, a best-effort identity read, a service request) and the
request the node cannot work without (:attr:`~SilentRequestConformance.required_request`).
The checks are behaviour, never a timing bound of the test machine: the node runs with
the client's timeout for the request at :data:`HOLD_TIMEOUT_S` (the delay runs answer after
:data:`HOLD_DELAY_S`), and each check reads the order of events against the silent request's
wait (from its entry in the simulator's receive log until its answer went out, the client's
timeout, or the service call that asked it returned):

* joint_states go on while it waits: :data:`SAMPLES_WHILE_WAITING` new samples (stamped by
  the node after the request reached the simulator) arrive before the wait ended. A node
  that waits behind the request publishes none in that time on any machine; the rate
  itself is a figure (``make bench``), not a verdict;
* ``~/stop`` and a jog are in the receive log after the silent request and before its wait
  ended. A stop that waited behind the request comes after the end of the wait on any
  machine; one that does not wait comes at once;
* the dead-man stop reaches the simulator after the last joint_command;
* a request the node asks on its own is named at WARN on /diagnostics with how often it went
  unanswered, and asked again after a growing back-off, not back to back;
* the connection diagnostic stays OK and the node does not connect again;
* a best-effort read muted at connect never keeps the node from connecting; a required one
  muted makes the connection error name it.

A figure a driver does not meet yet is marked for that driver with ``pytest.mark.xfail(
strict=True)`` by :attr:`~SilentRequestConformance.silent_request_gaps` (strict: it fails the
day the driver meets it).
"""

from __future__ import annotations

import itertools
import re
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance_rig import (
    ERROR,
    OK,
    ConformanceHelpers,
    ConformanceRig,
)

WARN = 1
#: the late answer of the ``delay`` runs on the suite's own node (s): later than a reply
#: should take, within most clients' timeouts
DELAY_S = 0.4
#: the client's timeout for the silent request while a check waits on it (s): the node runs
#: with its ``timeout_parameter`` at this (every driver's parameter takes it), so that the
#: ask is still waiting however long a stop or a sample takes through a loaded machine
HOLD_TIMEOUT_S = 5.0
#: the late answer of the ``delay`` runs on the holding node (s): within the held timeout,
#: so the answer comes and ends the wait, as a late answer does
HOLD_DELAY_S = 4.0
#: new joint_states samples that must arrive while the silent request waits (at 50 Hz a
#: node gives them in a tenth of a second; one that waits behind the request gives none)
SAMPLES_WHILE_WAITING = 5
#: asks of a muted request the back-off check waits for (two intervals between them)
BACKOFF_ASKS = 3
#: what a count in a diagnostics text looks like ("3 time(s)", "(2x)")
COUNT = re.compile(r'\d+ ?(time|x\b)')
MODES = ('mute', 'delay')


@dataclass(frozen=True)
class SilentRequest:
    """One kind of request of a driver, named as its simulator's ``mute`` takes it."""

    kind: str                      # 'sensor getter', 'status register', 'identity read', ...
    request: str                   # the device's own name for it
    #: the node asks it on its own, again and again (sensor, register): diagnostics and
    #: back-off apply
    periodic: bool = False
    #: asked once at connect (identity, read-backs): best effort, checked by a restart
    at_connect: bool = False
    #: the node parameter holding the client's timeout for one ask (s)
    timeout_parameter: str = ''
    #: a topic whose subscriber makes the node ask it (the IMU getter: ~/imu), and its type
    topic: tuple[str, type] | None = None
    #: (service type, name under the node, request) a call of which sends it
    service: tuple[type, str, Callable[[], Any]] | None = None


@dataclass
class RequestLog:
    """The simulator's receive log with the time each request was handled."""

    entries: list[tuple[float, str]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)
    arrived: threading.Condition = field(init=False)

    def __post_init__(self) -> None:
        self.arrived = threading.Condition(self.lock)

    def add(self, request: str) -> None:
        with self.lock:
            self.entries.append((time.monotonic(), request))
            self.arrived.notify_all()

    def mark(self) -> int:
        with self.lock:
            return len(self.entries)

    def since(self, mark: int) -> list[tuple[float, str]]:
        with self.lock:
            return list(self.entries[mark:])

    def wait_for(self, name: str, mark: int, timeout: float) -> tuple[int, float]:
        """The index and time of the first ``name`` logged from ``mark`` on."""
        deadline = time.monotonic() + timeout
        with self.lock:
            while True:
                for index in range(mark, len(self.entries)):
                    stamp, request = self.entries[index]
                    if named(request, name):
                        return index, stamp
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f'{name} never reached the simulator in {timeout:g} s')
                self.arrived.wait(left)


def named(logged: str, name: str) -> bool:
    """Whether a receive-log entry is the request ``name``: entries are words, the request
    one of them ("IMU_GetRoll", "service IDS", "MOVE pan 0.1 0.5")."""
    return name in logged.split()


def wait_until(condition: Callable[[], bool], timeout: float) -> bool:
    """Whether ``condition`` came true within ``timeout`` (polled; False, not an error)."""
    try:
        wait_for(condition, timeout, 'condition')
    except TimeoutError:
        return False
    return True


def stamp_of(msg: JointState) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


class SilentRequestConformance(ConformanceHelpers):
    """Mixed into :class:`~gimbal_driver_testing.conformance.DriverConformance`."""

    jog: tuple[str, float]
    small_move: dict[str, float]
    #: the driver's requests by kind (see :class:`SilentRequest`)
    silent_requests: Sequence[SilentRequest] = ()
    #: (request, a text the connection error shows for it): what the node cannot work
    #: without; '' if the protocol has no request the connection hangs on
    required_request: tuple[str, str] = ('', '')
    #: the request that opens a connection (counted: a silent request must not make the
    #: node connect again); '' where the protocol has none
    handshake_request: str = ''
    #: (figure, request or '*') -> what the driver lacks for it, marked xfail(strict=True);
    #: figures: 'cost', 'stop', 'jog', 'connect'
    silent_request_gaps: dict[tuple[str, str], str] = {}

    # ------------------------------------------------------------ parametrisation
    def pytest_generate_tests(self, metafunc: pytest.Metafunc) -> None:
        """One case per (request, mute|delay) for the tests that take ``silent``."""
        if 'silent' not in metafunc.fixturenames:
            return
        figure = FIGURES[metafunc.function.__name__]
        wanted = (lambda r: r.at_connect) if figure == 'connect' else (
            lambda r: not r.at_connect)
        cases = []
        for request in (r for r in self.silent_requests if wanted(r)):
            for mode in MODES:
                gap = (self.silent_request_gaps.get((figure, request.request))
                       or self.silent_request_gaps.get((figure, '*')))
                marks = [pytest.mark.xfail(strict=True, reason=gap)] if gap else []
                cases.append(pytest.param((request, mode), marks=marks,
                                          id=f'{request.request}-{mode}'))
        if not cases:
            cases = [pytest.param(None, marks=pytest.mark.skip(
                reason=f'{self.driver} has no request of this kind'), id='none')]
        metafunc.parametrize('silent', cases)

    # ------------------------------------------------------------------ helpers
    def request_log(self, rig: ConformanceRig) -> RequestLog:
        """The simulator's receive log, timed (wraps the handle's ``record`` once)."""
        sim = rig.sim
        log = getattr(sim, 'timed_log', None)
        if log is None:
            log = RequestLog()
            plain = sim.record

            def record(request: str, detail: str = '') -> None:
                log.add(f'{request} {detail}' if detail else request)
                plain(request, detail)

            sim.record = record  # type: ignore[method-assign]  # the handle's own hook
            sim.timed_log = log
        return log

    @contextmanager
    def silenced(self, rig: ConformanceRig, request: SilentRequest, mode: str,
                 delay: float = DELAY_S) -> Iterator[None]:
        """The simulator leaves ``request`` unanswered (mute) or answers it ``delay`` late."""
        if mode == 'mute':
            rig.sim.mute(request.request)
        else:
            rig.sim.delay(request.request, delay)
        subscribed = request.topic is not None
        if subscribed:
            rig.ros.subscribe(f'/{self.node_name}/{request.topic[0]}', request.topic[1])
        try:
            yield
        finally:
            rig.sim.clear()
            if subscribed:
                rig.ros.unsubscribe(f'/{self.node_name}/{request.topic[0]}')

    def wait_window(self, rig: ConformanceRig, request: SilentRequest, mode: str) -> float:
        """How long one ask of ``request`` waits for its answer, by the node's own timeout."""
        timeout = (float(rig.ros.get_parameter(self.node_name, request.timeout_parameter))
                   if request.timeout_parameter else float('inf'))
        return min(timeout, DELAY_S) if mode == 'delay' else timeout

    def asking(self, rig: ConformanceRig, request: SilentRequest
               ) -> tuple[Callable[[], None], list[float]]:
        """A way to make the node send ``request`` now (a service call, in its own thread;
        for a request the node asks on its own, nothing) and the times the calls returned."""
        returned: list[float] = []
        if request.service is None:
            return (lambda: None), returned
        srv_type, name, make = request.service

        def call() -> None:
            try:
                rig.ros.call(srv_type, self.srv(name), make(), timeout=30.0)
            except TimeoutError:
                pass  # the node was restarted under it: the call has ended all the same
            finally:
                returned.append(time.monotonic())

        def start() -> None:
            threading.Thread(target=call, daemon=True, name=f'call {name}').start()

        return start, returned

    def holding_node(self, rig: ConformanceRig, request: SilentRequest) -> None:
        """A fresh node whose client waits :data:`HOLD_TIMEOUT_S` for ``request`` (the next
        test that needs the suite's own parameters restarts it with them)."""
        extra = ([f'{request.timeout_parameter}:={HOLD_TIMEOUT_S}']
                 if request.timeout_parameter else [])
        rig.stop_node()
        rig.ros.subscribers_matched('joint_command', 0)  # the old node is gone
        rig.start_node(*extra)
        rig.ros.subscribers_matched('joint_command', 1)  # a jog reaches the new one
        rig.ros.call(Trigger, self.srv('stop'), Trigger.Request())  # its services are up

    def from_a_position_move(self, rig: ConformanceRig, joint: str) -> None:
        """End a position move of ``joint`` first, so that every jog case starts from the
        same state whatever ran before (a device may need a mode switch for the first jog
        after a position move: Capture's MOT_SetSpeedMode). Two moves: the first may find
        the axis at its target already and send nothing."""
        there = self.small_move.get(joint, 0.0)
        for target in (there, there - 0.1):
            rig.ros.publish('joint_command', JointState(name=[joint], position=[target]))
            self.wait_positions(rig.ros, {joint: target})
        self.wait_stopped(rig, joint, f'the position move of {joint} to end')

    def wait_ended(self, arrived: float, mode: str, returned: list[float],
                   request: SilentRequest, calls: int) -> Callable[[], float]:
        """When the wait of the ask that arrived at ``arrived`` ended, as far as known now:
        its late answer went out (delay), the client's timeout (a node with
        :meth:`holding_node`'s timeout), or the service call that asked it returned."""
        timeout = HOLD_TIMEOUT_S if request.timeout_parameter else float('inf')
        end = arrived + (min(timeout, HOLD_DELAY_S) if mode == 'delay' else timeout)
        return lambda: min([end, *returned[calls:calls + 1]])

    def sent_while_waiting(self, rig: ConformanceRig, log: RequestLog, index: int,
                           ended: Callable[[], float], what: str) -> tuple[float, str]:
        """The first motion request logged after entry ``index`` (the silent request), which
        must have come before the silent request's wait ``ended``; fails naming the order."""
        def first() -> tuple[float, str] | None:
            motions = self.motion_after(rig, log, index + 1)
            return motions[0] if motions else None

        found = wait_until(lambda: first() is not None or time.monotonic() > ended(),
                           HOLD_TIMEOUT_S + 60.0) and first()
        end = ended()
        arrived = log.since(index)[0][0]
        after = [(round(t - arrived, 3), r) for t, r in log.since(index)
                 if not r.startswith(('MOT_GetLoadPosition', 'MOT_GetMotorSpeed'))][:40]
        assert found and found[0] < end, (
            f'{what} reached the simulator only after the silent request stopped waiting: '
            f'its wait ended {end - arrived:.3f} s after it arrived, {what} '
            f'{f"came {found[0] - arrived:.3f} s after it ({found[1]})" if found else "never"}'
            f'; the receive log from the silent request on: {after}')
        return found

    def connection_levels(self, rig: ConformanceRig, since: int) -> list[tuple[int, str]]:
        arrays = rig.ros.subscribe('/diagnostics', DiagnosticArray)[since:]
        name = f'{self.node_name}: connection'
        return [(s.level[0], s.message) for a in list(arrays) for s in a.status
                if s.name == name]

    def handshakes(self, log: RequestLog, mark: int) -> int:
        return sum(1 for _, r in log.since(mark)
                   if self.handshake_request and named(r, self.handshake_request))

    @contextmanager
    def waiting_request(self, rig: ConformanceRig, request: SilentRequest, mode: str
                        ) -> Iterator[tuple[RequestLog, int, Callable[[], float]]]:
        """The node (a :meth:`holding_node`) asks ``request`` once more while the simulator
        keeps it silent; yields the receive log, the ask's index in it and when its wait
        ended (:meth:`wait_ended`)."""
        log = self.request_log(rig)
        with self.silenced(rig, request, mode, HOLD_DELAY_S):
            ask, returned = self.asking(rig, request)
            mark, calls = log.mark(), len(returned)
            ask()
            index, arrived = log.wait_for(request.request, mark, 60.0)
            yield log, index, self.wait_ended(arrived, mode, returned, request, calls)

    def samples_while_waiting(self, states: list[JointState], arrived: float,
                              ended: Callable[[], float], what: str) -> None:
        """:data:`SAMPLES_WHILE_WAITING` new joint_states samples (by the node's stamps, the
        time its device data arrived: later than the ask's arrival at the simulator) came
        in before the silent request's wait ``ended``; fails naming what came."""
        since = arrived + time.time() - time.monotonic()  # the arrival on the node's clock

        def fresh() -> int:
            return len({stamp for m in list(states) if (stamp := stamp_of(m)) > since})

        wait_until(lambda: fresh() >= SAMPLES_WHILE_WAITING or time.monotonic() > ended(),
                   HOLD_TIMEOUT_S + 60.0)
        count, now, end = fresh(), time.monotonic(), ended()
        assert count >= SAMPLES_WHILE_WAITING and now < end, (
            f'joint_states did not go on while {what} waited: {count} new sample(s) of '
            f'{SAMPLES_WHILE_WAITING} by the end of its wait, {end - arrived:.3f} s after it '
            f'arrived (seen {now - arrived:.3f} s after)')

    # ------------------------------------------------------------------- tests
    @pytest.mark.ros
    def test_a_silent_request_costs_only_itself(self, conformance_rig: ConformanceRig,
                                                silent) -> None:
        rig, (request, mode) = conformance_rig, silent
        if request.periodic and mode == 'mute':
            # on the suite's own node, whose timeout sets the back-off
            rig.shared_node()
            log, window = self.request_log(rig), self.wait_window(rig, request, mode)
            with self.silenced(rig, request, mode):
                mark = log.mark()
                log.wait_for(request.request, mark, 30.0)
                self.check_named_at_warn(rig, request)
                self.check_backoff(log, request, mark, window)
        self.holding_node(rig, request)
        diagnostics = rig.ros.subscribe('/diagnostics', DiagnosticArray)
        states, seen = rig.ros.subscribe('joint_states', JointState), len(diagnostics)
        with self.waiting_request(rig, request, mode) as (log, mark, ended):
            arrived = log.since(mark)[0][0]
            self.samples_while_waiting(states, arrived, ended, f'{request.request} {mode}')
            # the connection as the node reports it through the wait and after its end
            assert wait_until(lambda: time.monotonic() > ended(), HOLD_TIMEOUT_S + 60.0)
            rig.ros.wait_for_message('/diagnostics', DiagnosticArray, lambda a: any(
                s.name == f'{self.node_name}: connection' for s in a.status), timeout=30)
        levels = self.connection_levels(rig, seen)
        assert levels and all(level == OK for level, _ in levels), (
            f'the connection left OK with only {request.request} {mode}d: {levels[-5:]}')
        assert self.handshakes(log, mark) == 0, f'the node connected again ({log.since(mark)})'

    def check_named_at_warn(self, rig: ConformanceRig, request: SilentRequest) -> None:
        """A status of the node at WARN names the request and how often it went unanswered."""
        def names_it(status: DiagnosticStatus) -> bool:
            text = ' '.join([status.message, *(f'{kv.key} {kv.value}' for kv in status.values)])
            return request.request in text and bool(COUNT.search(text))

        def found(array: DiagnosticArray) -> bool:
            return any(names_it(s) for s in self.node_statuses(array))

        try:
            array = rig.ros.wait_for_message('/diagnostics', DiagnosticArray, found, timeout=30)
        except TimeoutError:
            raise AssertionError(f'/diagnostics never named {request.request} with a count'
                                 ) from None
        levels = [s.level[0] for s in self.node_statuses(array) if names_it(s)]
        assert WARN in levels and ERROR not in levels, levels

    def check_backoff(self, log: RequestLog, request: SilentRequest, mark: int,
                      window: float) -> None:
        """The muted request is asked again, never at once: each pause is longer than its
        timeout. Each form of it in the log is one request: Capture's per-axis register read
        for axis 1 and for axis 2 are two (the read of axis 2 follows axis 1's timeout).

        That the pauses grow (the back-off doubles) is checked on an injected clock
        (``gimbal_driver_common/test/test_unanswered.py``), not here: through processes
        each pause also holds the poll's alignment and, for axis 2, axis 1's timeout when
        both come due in one refresh, so two pauses 1 s apart by the back-off read 2.23 and
        2.06 s in a pinned run."""
        def series() -> dict[str, list[float]]:
            asked: dict[str, list[float]] = {}
            for t, r in log.since(mark):
                if named(r, request.request):
                    asked.setdefault(r, []).append(t)
            return asked

        wait_for(lambda: (asked := series()) and all(len(times) >= BACKOFF_ASKS
                                                     for times in asked.values()), 60.0,
                 f'{BACKOFF_ASKS} asks of each form of {request.request}')
        for form, times in series().items():
            gaps = [later - earlier
                    for earlier, later in itertools.pairwise(times[:BACKOFF_ASKS])]
            assert all(gap > window for gap in gaps), (
                f'{form} asked back to back (gaps {gaps}, its timeout {window:g} s)')

    def motion_after(self, rig: ConformanceRig, log: RequestLog, mark: int
                     ) -> list[tuple[float, str]]:
        return [(t, r) for t, r in log.since(mark) if rig.sim.motion(r)]

    @pytest.mark.ros
    def test_stop_goes_out_while_a_silent_request_waits(
            self, conformance_rig: ConformanceRig, silent) -> None:
        rig, (request, mode) = conformance_rig, silent
        self.holding_node(rig, request)
        with self.waiting_request(rig, request, mode) as (log, index, ended):
            rig.ros.call(Trigger, self.srv('stop'), Trigger.Request())
            self.sent_while_waiting(rig, log, index, ended, '~/stop')

    @pytest.mark.ros
    def test_a_jog_goes_out_while_a_silent_request_waits(
            self, conformance_rig: ConformanceRig, silent) -> None:
        rig, (request, mode) = conformance_rig, silent
        joint, velocity = self.jog
        self.holding_node(rig, request)
        self.from_a_position_move(rig, joint)
        with self.waiting_request(rig, request, mode) as (log, index, ended):
            rig.ros.publish('joint_command', JointState(name=[joint], velocity=[velocity]))
            last_command = time.monotonic()
            self.sent_while_waiting(rig, log, index, ended, 'the jog')
            assert wait_until(lambda: rig.sim.moving(joint), 20.0), f'{joint} never moved'
            # no further joint_command: the dead-man stop must reach the device
            self.wait_stopped(rig, joint, 'the dead-man stop of the jog')
            motions = self.motion_after(rig, log, index + 1)
            assert motions and motions[-1][0] > last_command, (
                f'no stop reached the simulator after the last joint_command: {motions}')

    @pytest.mark.ros
    def test_a_silent_best_effort_read_never_keeps_the_node_from_connecting(
            self, conformance_rig: ConformanceRig, silent) -> None:
        rig, (request, mode) = conformance_rig, silent
        log = self.request_log(rig)
        mark = log.mark()
        rig.stop_node()
        with self.silenced(rig, request, mode):
            node = rig.start_node('reconnect_period:=0.3', wait_active=False)
            self.wait_connection(rig.ros, OK, timeout=60.0)
            assert any(named(r, request.request) for _, r in log.since(mark)), (
                f'the node never asked {request.request} at connect')
            if mode == 'mute':
                node.wait_for_output(request.request)
                lines = [line for line in node.output().splitlines()
                         if request.request in line]
                assert any('WARN' in line for line in lines), lines
        rig.ros.wait_for_message('joint_states', JointState, timeout=30)
        rig.stop_node()

    @pytest.mark.ros
    def test_a_silent_required_request_names_itself(
            self, conformance_rig: ConformanceRig) -> None:
        rig, (name, text) = conformance_rig, self.required_request
        if not name:
            pytest.skip(f'{self.driver}: no request the connection hangs on')
        rig.stop_node()
        rig.sim.mute(name)
        try:
            node = rig.start_node('reconnect_period:=0.3', wait_active=False)
            self.wait_connection(rig.ros, ERROR, timeout=60.0)
            node.wait_for_output(text)
            lines = [line for line in node.output().splitlines() if text in line]
            assert any('ERROR' in line for line in lines), lines
        finally:
            rig.sim.clear()
            rig.stop_node()


FIGURES = {
    'test_a_silent_request_costs_only_itself': 'cost',
    'test_stop_goes_out_while_a_silent_request_waits': 'stop',
    'test_a_jog_goes_out_while_a_silent_request_waits': 'jog',
    'test_a_silent_best_effort_read_never_keeps_the_node_from_connecting': 'connect',
}
