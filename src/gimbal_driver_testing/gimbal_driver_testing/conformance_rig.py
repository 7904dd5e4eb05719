"""The rig a conformance test class runs on: simulator handle, shared node, ROS client.

Split from :mod:`conformance_testing` (the tests themselves) so each stays short.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState

from gimbal_driver_common import registry
from gimbal_driver_common.command_stream import LONGEST_GAP_KEY
from gimbal_driver_common.sim_handle import SimHandle, make_handle
from gimbal_driver_testing import DomainLease, ManagedProcess, wait_for
from gimbal_driver_testing.ros import RosTestClient, joint_positions
from gimbal_msgs.action import MoveTo

if TYPE_CHECKING:
    from gimbal_driver_testing.conformance import DriverConformance

REJECTED = 'joint_command rejected, nothing sent'
#: the diagnostics part that counts refused joint_commands (gimbal_driver_common.rejections)
COMMAND_PART = 'joint_command'
OK = 0
WARN = 1
ERROR = 2
STALE = 3


#: the joint_states frequency window interface.md documents: OK within ±10 % of the
#: expected rate (diagnostic_updater's FrequencyStatusParam tolerance), WARN outside
FREQUENCY_TOLERANCE = 0.1


def frequency_level_fits(status: DiagnosticStatus) -> bool:
    """Whether a measured ``joint_states frequency`` status has the level its own measured
    rate gives by the documented window, and a rate of published messages (> 0).

    Through a process this is what holds on any machine: a node starved of CPU (8 workers
    on 2 cores) really publishes below its rate for a while, and then WARN is the truth.
    The level logic itself is tested on an injected clock (test_core.py, FrequencyMonitor).
    """
    values = {kv.key: kv.value for kv in status.values}
    expected, measured = float(values['expected_hz']), measured_hz(status)
    low, high = expected * (1 - FREQUENCY_TOLERANCE), expected * (1 + FREQUENCY_TOLERANCE)
    # measured_hz is rounded to 0.01: a rate on the edge may read either way
    edge = min(abs(measured - low), abs(measured - high)) <= 0.01
    level = OK if low <= measured <= high else WARN
    return measured > 0 and (status.level[0] == level or edge)


def measured_hz(status: DiagnosticStatus) -> float:
    """The rate a ``joint_states frequency`` status measured (its ``measured_hz`` value)."""
    return float({kv.key: kv.value for kv in status.values}.get('measured_hz', 0.0))


def command_counts(status: DiagnosticStatus) -> dict[str, int]:
    """The counts of a ``joint_command`` diagnostics part, by key (every value but the
    longest delivery gap, which is in seconds)."""
    return {kv.key: int(kv.value) for kv in status.values if kv.key != LONGEST_GAP_KEY}


class GoalStatus:
    """action_msgs/GoalStatus codes (kept here: the package does not depend on action_msgs)."""

    STATUS_SUCCEEDED = 4
    STATUS_CANCELED = 5
    STATUS_ABORTED = 6


#: the simulator as the suite sees it: the driver's registry handle (link parameters, the
#: receive side's motion_received, moving, drop_link, close), started in the test process
SimulatorHandle = SimHandle


class ConformanceRig:
    """One simulator, a leased domain, a test client and the node currently under test."""

    def __init__(self, suite: DriverConformance, workdir: Path) -> None:
        self.suite = suite
        self.workdir = workdir
        self.presets_file = workdir / 'presets.yaml'
        self._lease = DomainLease()
        self.domain = self._lease.acquire()
        self.node: ManagedProcess | None = None
        self._node_extra: tuple[str, ...] | None = None
        self.sim: SimulatorHandle | None = None
        self.ros: RosTestClient | None = None
        try:
            self.sim = suite.start_simulator(workdir, self.domain)
            self.ros = RosTestClient(self.domain, 'conformance_client')
        except BaseException:
            self.close()
            raise

    def node_parameters(self, extra: Sequence[str] = ()) -> list[str]:
        assert self.sim is not None
        return [*self.sim.link_parameters(), f'presets_file:={self.presets_file}',
                *self.suite.node_parameters(), *extra]

    def start_node(self, *extra: str, wait_active: bool = True,
                   namespace: str = '') -> ManagedProcess:
        """(Re)start the node with the suite's parameters plus ``extra``, in ``namespace``
        (``-r __ns:=``) if given."""
        self.stop_node()
        args = ['--ros-args', *[x for p in self.node_parameters(extra) for x in ('-p', p)]]
        if namespace:
            args += ['-r', f'__ns:={namespace}']
        assert self.ros is not None
        states = self.ros.subscribe(f'{namespace}/joint_states' if namespace else
                                    'joint_states', JointState)
        seen = len(states)
        self.node = ManagedProcess.ros(self.suite.package, self.suite.node_executable,
                                       self.domain, args)
        self._node_extra = (*extra, *([f'__ns:={namespace}'] if namespace else []))
        if wait_active:
            wait_for(lambda: len(states) > seen or not self.node.running, 60.0,
                     f'joint_states from {self.suite.node_executable}')
            assert self.node.running, self.node.output()[-3000:]
        return self.node

    def shared_node(self) -> ManagedProcess:
        """The node with the suite's own parameters, restarted if a test changed it."""
        if self.node is None or not self.node.running or self._node_extra != ():
            self.start_node()
        assert self.node is not None
        return self.node

    def stop_node(self) -> None:
        if self.node is not None:
            self.node.stop()
            self.node = None
            self._node_extra = None

    def close(self) -> None:
        if self.ros is not None:
            self.ros.close()
        tail = self.node.output()[-3000:] if self.node is not None else ''
        self.stop_node()
        if self.sim is not None:
            self.sim.close()
        self._lease.release()
        if tail:
            print(f'--- {self.suite.node_executable} log (tail) ---\n{tail}')


@functools.cache
def registered_spec(name: str) -> registry.DriverSpec:
    """The registry's spec of ``name``, looked up once per test process.

    Each lookup lists every ``sys.path`` entry again (``importlib.metadata``), and a rig
    asks for its spec on every diagnostic wait. A mid-case lookup in a pinned run came back
    without the turret (docs/testing.md, "Found by the whole pinned run of 2026-12-03").
    """
    return registry.driver(name)


class RegisteredDriver:
    """A process-test suite's driver, from the registry: set ``driver`` (the spec's name);
    the package, executables, node name and simulator follow from its spec."""

    driver: str = ''

    @property
    def spec(self) -> registry.DriverSpec:
        return registered_spec(self.driver)

    @property
    def package(self) -> str:
        return self.spec.package

    @property
    def node_executable(self) -> str:
        return self.spec.node_executable

    @property
    def node_name(self) -> str:
        return self.spec.node_name

    def start_simulator(self, workdir: Path, domain: int) -> SimulatorHandle:
        """The registry spec's simulator handle with the process tests' settings, started."""
        handle = make_handle(self.spec, workdir, process_tests=True)
        handle.start()
        return handle


class ConformanceHelpers(RegisteredDriver):
    """Waits and requests the conformance tests share (attributes come from the suite)."""

    tolerance: float
    far_move: tuple[str, float, float]

    def srv(self, name: str) -> str:
        return f'/{self.node_name}/{name}'

    def move_to(self, ros: RosTestClient, targets: dict[str, float],
                velocities: Sequence[float] = (), timeout: float = 60.0,
                cancel_after: float | None = None):
        goal = MoveTo.Goal(joint_names=list(targets), positions=list(targets.values()),
                           velocities=list(velocities))
        return ros.run_action(MoveTo, self.srv('move_to'), goal, timeout=timeout,
                              cancel_after=cancel_after)

    def wait_positions(self, ros: RosTestClient, targets: dict[str, float],
                       timeout: float = 30.0) -> JointState:
        return ros.wait_for_message(
            'joint_states', JointState,
            lambda m: all(abs(joint_positions(m).get(j, math.inf) - p) <= self.tolerance
                          for j, p in targets.items()), timeout=timeout)

    def wait_stopped(self, rig: ConformanceRig, joint: str, what: str) -> None:
        assert rig.sim is not None
        wait_for(lambda: not rig.sim.moving(joint), 20.0, what)

    def start_far_move(self, rig: ConformanceRig) -> None:
        """A slow joint_command move toward ``far_move`` that the device shows as motion.

        Published again (the same target) every half second until the device moves: a node
        just started may not have matched this client's publisher yet, and a message sent
        before that is lost (volatile). A pinned run's U-Camera node never saw the one
        message of a restarted node's first move."""
        joint, position, speed = self.far_move
        ros, sim = rig.ros, rig.sim
        assert ros is not None and sim is not None
        command = JointState(name=[joint], position=[position], velocity=[speed])
        sent = [-math.inf]

        def moving() -> bool:
            if sim.moving(joint):
                return True
            if time.monotonic() - sent[0] >= 0.5:
                ros.publish('joint_command', command)
                sent[0] = time.monotonic()
            return False

        wait_for(moving, 20.0, f'{joint} to start its slow move')

    def assert_short_of_far_target(self, rig: ConformanceRig) -> None:
        joint, position, _ = self.far_move
        assert rig.ros is not None
        msg = rig.ros.wait_for_message('joint_states', JointState, timeout=20)
        assert abs(joint_positions(msg)[joint] - position) > 0.1, 'stopped short of target'

    def rejections(self, ros: RosTestClient,
                   predicate: Callable[[dict[str, int]], bool] = lambda counts: True,
                   timeout: float = 30.0) -> dict[str, int]:
        """The node's refused-command counts (the ``joint_command`` diagnostics part: totals
        ``rejected``/``refused`` and ``<kind>: <reason>``) from a fresh /diagnostics message,
        the first one whose counts satisfy ``predicate``."""
        status = ros.wait_for_diagnostic(
            self.node_name, COMMAND_PART, lambda s: predicate(command_counts(s)), timeout)
        return command_counts(status)

    def node_statuses(self, array: DiagnosticArray) -> list[DiagnosticStatus]:
        prefix = f'{self.node_name}: '
        return [s for s in array.status if s.name.startswith(prefix)]

    def wait_connection(self, ros: RosTestClient, level: int, timeout: float = 30.0,
                        since: int | None = None) -> DiagnosticStatus:
        return ros.wait_for_diagnostic(self.node_name, 'connection',
                                       lambda s: s.level[0] == level, timeout=timeout,
                                       since=since)
