"""`make soak`: every driver against its simulator under faults and random ROS traffic at once.

Per driver (one after the other, each in a ROS domain of its own): the simulator runs in this
process, the node as its own process. Two loads run together until ``--seconds`` (SOAK_S)
have passed and every fault of the driver's schedule was injected at least once:

* a fault schedule (main thread): link drop, silence, garbage bytes, lost and malformed
  frames, NACKs, device fault bits (then ``~/reset_faults``), a simulator restart, and a
  lifecycle deactivate/activate once per round; in a seeded random order;
* random ROS traffic (a second thread), valid and invalid: joint_command with NaN, inf,
  unknown names, mismatched lengths and empty; every service with out-of-range and absurd
  values; move_to and home goals with cancels; invalid lifecycle transitions; parameter sets
  with bad values.

Then the faults heal and the soak checks the node: it prints one JSON report per driver with a
``pass`` per criterion and exits 1 if any criterion failed. Randomness is seeded (``--seed``,
printed in the report); waits are for conditions, never fixed sleeps for a result.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import logging
import math
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from soak_targets import make_handle, soak_targets
from std_srvs.srv import Trigger

from gimbal_driver_common.registry import DriverSpec, parameter_arguments
from gimbal_driver_common.sim_handle import Fault, SimHandle
from gimbal_driver_testing import DomainLease, ManagedProcess, wait_for
from gimbal_driver_testing.ros import _TYPE_SUPPORT_LOCK, RosTestClient
from gimbal_msgs.action import Home, MoveTo
from gimbal_msgs.srv import ClearPreset, GotoPreset, ListPresets, SetPreset, StartScan

#: a service call or action step not answered within this is a failure
ANSWER_TIMEOUT_S = 10.0
#: the slowest answers the report lists (what, when, seconds)
SLOWEST_LISTED = 5
#: unanswered calls that get a py-spy dump of the node's threads in the report
STACK_DUMPS = 3
RECONNECT_PERIOD_S = 1.0
#: a link fault passes when joint_states resume within this (s): "it resumes", on any
#: machine. How soon is a figure (``worst_s``, and the faults over ``reference_s``,
#: reconnect_period + 1 s, in ``over_reference``), not a verdict: one CI run on a slower
#: machine resumed 2.48 s after a link drop (docs/testing.md)
RESUME_DEADLINE_S = 30.0
#: allowed growth of the node between the start and the end of a soak (a 10 min soak
#: stays far below; a leak of one reconnect's worth of buffers or threads per fault does not)
RSS_GROWTH_BOUND_MB = 40.0
THREAD_GROWTH_BOUND = 4
STARTUP_TIMEOUT_S = 90.0
GOAL_TOLERANCE = 0.05  # rad (m): joint_states this close to a move's goal = converged
ABSURD_FLOATS = (math.nan, math.inf, -math.inf, 1e308, -1e9, 1e6, -0.0)
ABSURD_STRINGS = ('', 'bogus', 'x' * 300, 'pan tilt', '../../etc/passwd', 'ÄÖÜ')


def proc_figures(pid: int) -> dict[str, float]:
    """RSS (MB) and thread count of a process, from /proc."""
    try:
        text = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return {'rss_mb': -1.0, 'threads': -1}
    rss = re.search(r'VmRSS:\s+(\d+)', text)
    threads = re.search(r'Threads:\s+(\d+)', text)
    if rss is None or threads is None:  # exited (a zombie has neither)
        return {'rss_mb': -1.0, 'threads': -1}
    return {'rss_mb': round(int(rss.group(1)) / 1024.0, 1), 'threads': int(threads.group(1))}


class Counters:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.values: dict[str, int] = {}
        self.unanswered: list[str] = []
        self.slowest: list[tuple[float, str, float]] = []  # (seconds, what, soak time)

    def add(self, key: str, count: int = 1) -> None:
        with self.lock:
            self.values[key] = self.values.get(key, 0) + count

    def missed(self, what: str) -> None:
        with self.lock:
            self.unanswered.append(what)

    def answered_in(self, seconds: float, what: str, at: float) -> None:
        with self.lock:
            self.slowest.append((seconds, what, at))
            self.slowest.sort(reverse=True)
            del self.slowest[SLOWEST_LISTED:]


class Soak:
    """One driver's soak: simulator, node process, client, both loads and the report."""

    def __init__(self, handle: SimHandle, domain: int, seconds: float, seed: int) -> None:
        self.handle = handle
        self.domain = domain
        self.seconds = seconds
        self.rng = random.Random(seed)
        self.traffic_rng = random.Random(seed + 1)
        self.counters = Counters()
        self.node: ManagedProcess | None = None
        self.ros: RosTestClient | None = None
        self.arrivals: list[float] = []
        self.arrivals_lock = threading.Lock()
        self.stop_traffic = threading.Event()
        self.pause_traffic = threading.Event()
        self.traffic_idle = threading.Event()
        self.resume_times: list[dict[str, object]] = []
        self.faults_done: dict[str, int] = {}
        self.warm_figures: dict[str, float] = {}
        self.moves_after_reset: list[dict[str, object]] = []
        self.lifecycle_cycles: list[dict[str, object]] = []
        self.node_inactive = threading.Event()
        self._service_clients: dict[str, Any] = {}
        self._action_clients: dict[str, ActionClient] = {}
        self.started = time.monotonic()
        self.stack_dumps: list[str] = []

    # ------------------------------------------------------------------ set-up
    @property
    def node_name(self) -> str:
        return self.spec.node_name

    @property
    def spec(self) -> DriverSpec:
        return self.handle.spec

    @property
    def final_goal(self) -> dict[str, float]:
        """The spec's move goal: a reachable goal for the final move (rad/m, per joint)."""
        return dict(zip(self.spec.joints, self.spec.move_goal, strict=False))

    @property
    def secrets(self) -> tuple[str, ...]:
        """Text that must never appear in the node log (the device password)."""
        return (self.spec.password,) if self.spec.password else ()

    def service(self, name: str) -> str:
        return f'/{self.node_name}/{name}'

    def start_node(self) -> None:
        parameters = {'publish_rate': 20.0, 'reconnect_period': RECONNECT_PERIOD_S,
                      'diagnostics_period': 0.5, 'command_timeout': 0.5,
                      'presets_file': str(self.handle.workdir / 'presets.yaml'),
                      **self.handle.node_parameters()}
        args = ['--ros-args', *parameter_arguments(parameters)]
        self.node = ManagedProcess.ros(self.spec.package, self.spec.node_executable,
                                       self.domain, args)
        self.node.keep_log = True  # the report names it (node_log)

    def on_joint_state(self, msg: JointState) -> None:
        with self.arrivals_lock:
            self.arrivals.append(time.monotonic())
            del self.arrivals[:-200]
        self.latest = msg

    def wait_streaming(self, count: int = 5, timeout: float = 30.0) -> bool:
        """Wait for ``count`` joint_states arriving from now on (the link is up and stays up)."""
        since = time.monotonic()

        def flowing() -> bool:
            with self.arrivals_lock:
                return sum(1 for t in self.arrivals if t > since) >= count
        try:
            wait_for(flowing, timeout, 'joint_states to flow', interval=0.02)
            return True
        except TimeoutError:
            return False

    def joint_states_after(self, moment: float, timeout: float) -> float | None:
        """Seconds from ``moment`` to the first joint_states after it, or None."""
        def first() -> float | None:
            with self.arrivals_lock:
                later = [t for t in self.arrivals if t > moment]
            return later[0] if later else None
        try:
            return wait_for(first, timeout, 'joint_states', interval=0.01) - moment
        except TimeoutError:
            return None

    # ------------------------------------------------------------------ calls
    def answered(self, future: Any, what: str) -> bool:
        """Wait for ``future``; one not done within ANSWER_TIMEOUT_S counts as unanswered
        (and the first few get a dump of the node's threads: what they were busy with)."""
        sent = time.monotonic()
        try:
            wait_for(future.done, ANSWER_TIMEOUT_S, what, interval=0.005)
        except TimeoutError:
            self.counters.missed(f'{what}: no answer within {ANSWER_TIMEOUT_S:g} s '
                                 f'(sent at soak time {sent - self.started:.1f} s)')
            if len(self.stack_dumps) < STACK_DUMPS:
                self.stack_dumps.append(self.dump_node_threads(what))
            return False
        done = time.monotonic()
        self.counters.answered_in(round(done - sent, 3), what, round(sent - self.started, 1))
        return True

    def dump_node_threads(self, what: str) -> str:
        """py-spy's stack dump of every node thread, to a file beside the node log."""
        assert self.node is not None
        path = Path(f'{self.node.log_path}.stacks-{len(self.stack_dumps) + 1}.txt')
        spy = Path(sys.executable).parent / 'py-spy'
        try:
            dump = subprocess.run([str(spy), 'dump', '--pid', str(self.node.process.pid)],
                                  capture_output=True, text=True, timeout=30, check=False)
            text = dump.stdout + dump.stderr
        except (OSError, subprocess.TimeoutExpired) as exc:
            text = f'py-spy dump failed: {exc}'
        path.write_text(f'{what}: unanswered\n{text}', encoding='utf-8')
        return str(path)

    def on_spin_thread(self, request: Callable[[], Any], what: str) -> Any | None:
        """Run an ActionClient ``*_async`` on the client's spin thread (rclpy#1123: called
        from this traffic thread, an answer the spin thread takes before the call has
        stored its future is dropped, and the future never completes: a lost answer that
        the node did send). None (and counted) if the spin thread does not run it in time."""
        try:
            return self.ros._on_spin_thread(request, ANSWER_TIMEOUT_S, what)
        except TimeoutError:
            self.counters.missed(f'{what}: the client executor did not send it within '
                                 f'{ANSWER_TIMEOUT_S:g} s')
            return None

    def call(self, srv_type: type, name: str, request: Any) -> Any | None:
        """Call a service; None (and counted) when it is not answered in time."""
        client = self._service_clients.get(name)
        if client is None:
            with _TYPE_SUPPORT_LOCK:
                client = self.ros.node.create_client(srv_type, name)
            self._service_clients[name] = client
        self.counters.add('calls')
        if not client.wait_for_service(timeout_sec=ANSWER_TIMEOUT_S):
            self.counters.missed(f'{name}: service not available')
            return None
        future = client.call_async(request)
        if not self.answered(future, name):
            client.remove_pending_request(future)
            return None
        return future.result()

    def action(self, action_type: type, name: str, goal: Any,
               cancel_after: float | None) -> Any | None:
        """Send a goal, cancel it after ``cancel_after`` s; the goal response, the cancel
        answer and the result must each come within ANSWER_TIMEOUT_S."""
        client = self._action_clients.get(name)
        if client is None:
            with _TYPE_SUPPORT_LOCK:
                client = ActionClient(self.ros.node, action_type, name)
            self._action_clients[name] = client
        self.counters.add('goals')
        if not client.wait_for_server(timeout_sec=ANSWER_TIMEOUT_S):
            self.counters.missed(f'{name}: action server not available')
            return None
        sent = self.on_spin_thread(lambda: client.send_goal_async(goal), f'{name} goal')
        if sent is None or not self.answered(sent, f'{name} goal response'):
            return None
        handle = sent.result()
        if not handle.accepted:
            self.counters.add('goals_rejected')
            return None
        result = self.on_spin_thread(handle.get_result_async, f'{name} result request')
        if result is None:
            return None
        if cancel_after is not None:
            deadline = time.monotonic() + cancel_after
            while time.monotonic() < deadline and not result.done():
                time.sleep(0.02)
            if not result.done():
                self.counters.add('cancels')
                cancel = self.on_spin_thread(handle.cancel_goal_async, f'{name} cancel')
                if cancel is None or not self.answered(cancel, f'{name} cancel'):
                    return None
        if not self.answered(result, f'{name} result'):
            return None
        return result.result().result

    def transition(self, transition_id: int) -> bool | None:
        reply = self.call(ChangeState, self.service('change_state'),
                          ChangeState.Request(transition=Transition(id=transition_id)))
        return None if reply is None else reply.success

    # ------------------------------------------------------------------ traffic
    def traffic_loop(self) -> None:
        rng = self.traffic_rng
        generators: list[Callable[[random.Random], None]] = [
            self.random_joint_command, self.random_joint_command, self.random_joint_command,
            self.random_common_service, self.random_common_service,
            self.random_extra_service, self.random_goal, self.random_parameter,
            self.random_lifecycle,
        ]
        while not self.stop_traffic.is_set():
            if self.pause_traffic.is_set():
                self.traffic_idle.set()
                time.sleep(0.05)
                continue
            self.traffic_idle.clear()
            if self.pause_traffic.is_set():  # paused between the check and the clear
                continue
            rng.choice(generators)(rng)
            time.sleep(rng.uniform(0.02, 0.15))
        self.traffic_idle.set()

    def valid_position(self, rng: random.Random, joint: str) -> float:
        low, high = self.handle.joint_range(joint)
        return rng.uniform(low, high)

    def random_joint_command(self, rng: random.Random) -> None:
        joints = list(self.spec.joints)
        kind = rng.choice(('move', 'jog', 'nan', 'inf', 'unknown', 'mismatch', 'empty'))
        msg = JointState()
        if kind == 'move':
            msg.name = rng.sample(joints, rng.randrange(1, len(joints) + 1))
            msg.position = [self.valid_position(rng, j) for j in msg.name]
        elif kind == 'jog':
            msg.name = [rng.choice(joints)]
            msg.position = [math.nan]
            msg.velocity = [rng.uniform(-0.2, 0.2)]
        elif kind == 'nan':
            msg.name, msg.position = joints[:1], [math.nan]
        elif kind == 'inf':
            msg.name, msg.position = joints[:1], [rng.choice((math.inf, -math.inf))]
            if rng.random() < 0.5:
                msg.position, msg.velocity = [math.nan], [math.inf]
        elif kind == 'unknown':
            msg.name, msg.position = [rng.choice(ABSURD_STRINGS)], [0.1]
        elif kind == 'mismatch':
            msg.name, msg.position = joints, [0.1] * (len(joints) + rng.choice((-1, 1)))
            msg.velocity = [0.1] * rng.randrange(0, 4)
        self.ros.publish('/joint_command', msg)
        self.counters.add('joint_commands')

    def random_common_service(self, rng: random.Random) -> None:
        joints = list(self.spec.joints)
        choice = rng.randrange(8)
        if choice == 0:
            self.call(Trigger, self.service(rng.choice(('stop', 'stop_scan', 'reset_faults'))),
                      Trigger.Request())
        elif choice == 1:
            names = rng.choice((joints, joints[:1], ['bogus'], []))
            count = len(names) + rng.choice((0, 0, 1, -1)) if names else rng.randrange(3)
            positions = [rng.choice((*ABSURD_FLOATS, 0.1, 0.2)) if rng.random() < 0.4
                         else self.valid_position(rng, joints[0]) for _ in range(max(0, count))]
            self.call(SetPreset, self.service('set_preset'), SetPreset.Request(
                index=rng.choice((0, 1, 2, 15, 16, 999, 65535)),
                name=rng.choice(ABSURD_STRINGS), use_current_position=rng.random() < 0.3,
                joint_names=names, positions=positions))
        elif choice == 2:
            self.call(GotoPreset, self.service('goto_preset'), GotoPreset.Request(
                index=rng.choice((0, 1, 2, 16, 65535)),
                speed=rng.choice((0.0, 0.3, *ABSURD_FLOATS))))
            self.call(Trigger, self.service('stop'), Trigger.Request())
        elif choice == 3:
            self.call(ListPresets, self.service('list_presets'), ListPresets.Request())
        elif choice == 4:
            self.call(ClearPreset, self.service('clear_preset'), ClearPreset.Request(
                index=rng.choice((0, 1, 3, 65535)), all=rng.random() < 0.2))
        else:
            def value() -> float:
                return rng.choice(ABSURD_FLOATS) if rng.random() < 0.3 else rng.uniform(-0.3,
                                                                                      0.3)
            self.call(StartScan, self.service('start_scan'), StartScan.Request(
                pattern=rng.choice(('sector', 'zigzag', 'snake', 'square', 'spiral', '')),
                pan_min=value(), pan_max=value(), tilt_min=value(), tilt_max=value(),
                speed=rng.choice((0.2, 0.5, 0.0, -1.0, math.nan, 1e9)),
                tilt_step=rng.choice((0.1, 0.0, -0.1, math.inf)),
                dwell=rng.choice((0.0, 0.5, -1.0, math.nan))))
            time.sleep(rng.uniform(0.0, 1.0))
            self.call(Trigger, self.service('stop_scan'), Trigger.Request())

    def random_extra_service(self, rng: random.Random) -> None:
        if not self.spec.soak.extra_services:
            self.random_common_service(rng)
            return
        name, type_name = rng.choice(sorted(self.spec.soak.extra_services.items()))
        srv_type = service_type(type_name)
        request = srv_type.Request()
        fill_randomly(request, rng)
        self.call(srv_type, self.service(name), request)

    def random_goal(self, rng: random.Random) -> None:
        joints = list(self.spec.joints)
        if rng.random() < 0.25:
            self.action(Home, self.service('home'),
                        Home.Goal(joint_names=rng.choice(([], joints[:1], ['bogus']))),
                        cancel_after=rng.uniform(0.0, 1.0))
            return
        goal = MoveTo.Goal(joint_names=list(joints))
        kind = rng.choice(('valid', 'valid', 'relative', 'nan', 'unknown', 'mismatch',
                           'far', 'empty'))
        goal.positions = [self.valid_position(rng, j) for j in joints]
        if kind == 'relative':
            goal.relative, goal.positions = True, [rng.uniform(-0.05, 0.05) for _ in joints]
        elif kind == 'nan':
            goal.positions[0] = rng.choice((math.nan, math.inf))
        elif kind == 'unknown':
            goal.joint_names[0] = rng.choice(ABSURD_STRINGS)
        elif kind == 'mismatch':
            goal.positions = goal.positions[:-1]
        elif kind == 'far':
            goal.positions[0] = rng.choice((1e6, -1e6, 100.0))
        elif kind == 'empty':
            goal.joint_names, goal.positions = [], []
        if rng.random() < 0.3:
            goal.velocities = [rng.choice((0.0, 0.3, -1.0, math.nan, 1e9)) for _ in joints]
        self.action(MoveTo, self.service('move_to'), goal, cancel_after=rng.uniform(0.0, 1.5))

    def random_parameter(self, rng: random.Random) -> None:
        joints = len(self.spec.joints)
        name, value = rng.choice((
            ('publish_rate', ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                            double_value=rng.choice((-5.0, 0.0, 1e9, math.nan)))),
            ('publish_rate', ParameterValue(type=ParameterType.PARAMETER_STRING,
                                            string_value='fast')),
            ('reconnect_period', ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                double_value=rng.choice((-1.0, math.inf)))),
            ('goal_tolerance', ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                              double_value=rng.choice((-1.0, math.nan)))),
            ('position_min', ParameterValue(type=ParameterType.PARAMETER_DOUBLE_ARRAY,
                                            double_array_value=[-1.0] * (joints + 1))),
            ('velocity_max', ParameterValue(type=ParameterType.PARAMETER_DOUBLE_ARRAY,
                                            double_array_value=[math.nan] * joints)),
            ('joint_names', ParameterValue(type=ParameterType.PARAMETER_STRING_ARRAY,
                                           string_array_value=['a', 'b'])),
            ('command_timeout', ParameterValue(type=ParameterType.PARAMETER_BOOL,
                                               bool_value=True)),
        ))
        self.call(SetParameters, self.service('set_parameters'),
                  SetParameters.Request(parameters=[Parameter(name=name, value=value)]))

    def random_lifecycle(self, rng: random.Random) -> None:
        # transitions that are invalid while the node is active: each must be refused
        if self.node_inactive.is_set():
            return
        self.transition(rng.choice((Transition.TRANSITION_CONFIGURE,
                                    Transition.TRANSITION_ACTIVATE,
                                    Transition.TRANSITION_CLEANUP, 99)))

    # ------------------------------------------------------------------ faults
    def inject(self, fault: Fault) -> None:
        self.handle_fault_start = time.monotonic()
        fault.inject(self.rng)
        healed = time.monotonic()
        self.faults_done[fault.name] = self.faults_done.get(fault.name, 0) + 1
        if fault.link:
            resumed = self.joint_states_after(healed, RESUME_DEADLINE_S)
            self.resume_times.append({
                'fault': fault.name,
                'resume_s': None if resumed is None else round(resumed, 3)})
        # the next fault starts once joint_states flow again (a garbage burst or lost
        # replies can make a driver re-open its link)
        self.wait_streaming()
        if fault.reset_faults:
            self.moves_after_reset.append(self.reset_and_move(fault.name))

    def reset_and_move(self, fault: str) -> dict[str, object]:
        """~/reset_faults, then a move (random traffic paused) that must converge: a driver
        that accepts commands after a fault while the device no longer moves fails here."""
        self.quiet_traffic()
        try:
            self.wait_streaming()
            reply = self.call(Trigger, self.service('reset_faults'), Trigger.Request())
            outcome = self.final_move(self.random_goal_positions())
        finally:
            self.pause_traffic.clear()
        return {'fault': fault,
                'reset_faults': None if reply is None else f'{reply.success}: {reply.message}',
                **outcome}

    def random_goal_positions(self) -> dict[str, float]:
        return {j: round(self.valid_position(self.rng, j), 3) for j in self.final_goal}

    def quiet_traffic(self) -> None:
        """Pause the random traffic and wait until its current request is done."""
        self.pause_traffic.set()
        self.traffic_idle.wait(3 * ANSWER_TIMEOUT_S)

    def lifecycle_cycle(self) -> None:
        """deactivate -> activate; the random traffic keeps running against the inactive node
        (its own lifecycle requests are held back then: configure/cleanup/activate would be
        valid there). The node must come back active with joint_states."""
        self.quiet_traffic()
        try:
            deactivated = self.transition(Transition.TRANSITION_DEACTIVATE)
            self.node_inactive.set()
        finally:
            self.pause_traffic.clear()
        time.sleep(self.rng.uniform(0.2, 1.0))  # traffic against the inactive node meanwhile
        self.quiet_traffic()
        try:
            activated = self.transition(Transition.TRANSITION_ACTIVATE)
            self.node_inactive.clear()
        finally:
            self.pause_traffic.clear()
        streaming = self.wait_streaming()
        self.faults_done['lifecycle_cycle'] = self.faults_done.get('lifecycle_cycle', 0) + 1
        self.lifecycle_cycles.append({'deactivated': deactivated, 'activated': activated,
                                      'joint_states_back': streaming})

    def fault_schedule(self) -> None:
        faults = self.handle.faults()
        deadline = time.monotonic() + self.seconds
        rounds = 0
        while rounds < 2 or time.monotonic() < deadline:
            order = list(faults)
            self.rng.shuffle(order)
            for fault in order:
                self.inject(fault)
                time.sleep(self.rng.uniform(0.5, 1.5))  # random traffic alone for a while
                if rounds > 1 and time.monotonic() >= deadline:
                    break
            self.lifecycle_cycle()
            rounds += 1
            if rounds == 1:
                # growth is measured from here: the first round has run every code path once
                # (thread pools, lazily imported modules, DDS entities are all there)
                self.warm_figures = proc_figures(self.node.process.pid)

    # ------------------------------------------------------------------ final checks
    def diagnostics_healthy(self, timeout: float) -> dict[str, object]:
        """Wait for a /diagnostics message where this node's connection is OK and none of its
        parts is ERROR or STALE."""
        seen: dict[str, object] = {}

        def healthy(array: DiagnosticArray) -> bool:
            mine = [s for s in array.status if s.name.startswith(f'{self.node_name}: ')]
            if not mine:
                return False
            seen.clear()
            seen.update({s.name: f'{level_name(s.level)} {s.message}' for s in mine
                         if level_name(s.level) != 'OK'})
            connection = [s for s in mine if s.name == f'{self.node_name}: connection']
            return bool(connection) and level_name(connection[0].level) == 'OK' and not any(
                level_name(s.level) in ('ERROR', 'STALE') for s in mine)
        try:
            self.ros.wait_for_message('/diagnostics', DiagnosticArray, healthy, timeout)
            return {'ok': True, 'not_ok_parts': dict(seen)}
        except TimeoutError:
            return {'ok': False, 'not_ok_parts': dict(seen)}

    def final_move(self, goal_positions: dict[str, float]) -> dict[str, object]:
        """~/stop, then a MoveTo that must succeed with joint_states at the goal."""
        self.call(Trigger, self.service('stop'), Trigger.Request())
        try:
            result, _, _ = self.ros.run_action(
                MoveTo, self.service('move_to'),
                MoveTo.Goal(joint_names=list(goal_positions),
                            positions=list(goal_positions.values())), timeout=90.0)
        except (TimeoutError, AssertionError) as exc:
            return {'converged': False, 'message': str(exc), 'goal': goal_positions}

        def error() -> float:
            latest = dict(zip(self.latest.name, self.latest.position, strict=False))
            return max(abs(latest.get(j, math.inf) - v) for j, v in goal_positions.items())
        with contextlib.suppress(TimeoutError):
            wait_for(lambda: error() < GOAL_TOLERANCE, 10.0, 'joint_states at the goal')
        return {'converged': bool(result.success) and error() < GOAL_TOLERANCE,
                'message': result.message, 'goal': goal_positions,
                'max_error': round(error(), 4)}

    # ------------------------------------------------------------------ run
    def run(self) -> dict[str, object]:
        handle = self.handle
        report: dict[str, object] = {'driver': handle.spec.node_name, 'seconds': self.seconds}
        handle.start()
        self.start_node()
        self.ros = RosTestClient(self.domain, f'soak_{handle.spec.node_name}')
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        with _TYPE_SUPPORT_LOCK:
            self.ros.node.create_subscription(JointState, '/joint_states', self.on_joint_state,
                                              qos)
        started = time.monotonic()
        try:
            if self.joint_states_after(0.0, STARTUP_TIMEOUT_S) is None:
                raise RuntimeError(f'no joint_states from {handle.spec.node_executable} within '
                                   f'{STARTUP_TIMEOUT_S:g} s:\n{self.node.output()[-3000:]}')
            self.ros.subscribe('/diagnostics', DiagnosticArray)
            start_figures = proc_figures(self.node.process.pid)
            traffic = threading.Thread(target=self.traffic_loop, name='soak-traffic',
                                       daemon=True)
            traffic.start()
            try:
                self.fault_schedule()
            finally:
                self.stop_traffic.set()
                traffic.join(timeout=3 * ANSWER_TIMEOUT_S + 5)
            self.call(Trigger, self.service('reset_faults'), Trigger.Request())
            self.call(Trigger, self.service('stop'), Trigger.Request())
            diagnostics = self.diagnostics_healthy(30.0)
            final = self.final_move(self.final_goal)
            end_figures = proc_figures(self.node.process.pid)
            alive = self.node.running
        finally:
            self.ros.close()
            exit_code = self.node.stop()
            handle.stop()
        log = self.node.output()
        report.update(self.criteria(start_figures, self.warm_figures, end_figures, alive,
                                    exit_code, log, diagnostics, final))
        report['wall_s'] = round(time.monotonic() - started, 1)
        report['node_log'] = self.node.log_path
        return report

    def criteria(self, start: dict, warm: dict, end: dict, alive: bool, exit_code: int,
                 log: str, diagnostics: dict, final: dict) -> dict[str, object]:
        reference = RECONNECT_PERIOD_S + 1.0
        resumes = [r['resume_s'] for r in self.resume_times]
        worst = max((math.inf if r is None else r for r in resumes), default=0.0)
        over = [r for r in self.resume_times
                if isinstance(t := r['resume_s'], float) and t > reference]
        tracebacks = log.count('Traceback (most recent call last)')
        expected = {f.name for f in self.handle.faults()}
        values = dict(self.counters.values)
        rss_growth = end['rss_mb'] - warm['rss_mb']
        thread_growth = end['threads'] - warm['threads']
        checks = {
            'every_fault_injected': {'value': sorted(expected - set(self.faults_done)) or 'yes',
                                     'pass': expected <= set(self.faults_done)},
            'unanswered_calls': {'value': len(self.counters.unanswered),
                                 'detail': self.counters.unanswered[:10],
                                 'node_thread_dumps': self.stack_dumps,
                                 'slowest_answers_s': [
                                     {'what': what, 'at_s': at, 'seconds': seconds}
                                     for seconds, what, at in self.counters.slowest],
                                 'pass': not self.counters.unanswered},
            'node_crashes': {'value': 0 if alive else 1, 'exit_code': exit_code,
                             'pass': alive and exit_code == 0},
            'tracebacks_in_log': {'value': tracebacks, 'pass': tracebacks == 0},
            'secrets_in_log': {'value': sum(log.count(s) for s in self.secrets),
                               'pass': not any(s in log for s in self.secrets)},
            'joint_states_resume_s': {'value': self.resume_times,
                                      'deadline_s': RESUME_DEADLINE_S, 'worst_s': worst,
                                      'reference_s': reference, 'over_reference': over,
                                      'pass': None not in resumes},
            'diagnostics_ok_after_heal': {'value': diagnostics['ok'],
                                          'not_ok_parts': diagnostics['not_ok_parts'],
                                          'pass': diagnostics['ok']},
            'rss_mb': {'start': start['rss_mb'], 'after_first_round': warm['rss_mb'],
                       'end': end['rss_mb'],
                       'growth': round(rss_growth, 1), 'bound': RSS_GROWTH_BOUND_MB,
                       'pass': rss_growth <= RSS_GROWTH_BOUND_MB},
            'threads': {'start': start['threads'], 'after_first_round': warm['threads'],
                        'end': end['threads'],
                        'growth': thread_growth, 'bound': THREAD_GROWTH_BOUND,
                        'pass': thread_growth <= THREAD_GROWTH_BOUND},
            'lifecycle_cycles_ok': {
                'value': self.lifecycle_cycles,
                'pass': bool(self.lifecycle_cycles) and all(
                    c['deactivated'] and c['activated'] and c['joint_states_back']
                    for c in self.lifecycle_cycles)},
            'moves_after_fault_reset': {
                'value': self.moves_after_reset,
                'pass': all(m.get('converged') for m in self.moves_after_reset)},
            'final_move_converges': {**final, 'pass': bool(final.get('converged'))},
        }
        return {
            'faults_injected': sum(self.faults_done.values()),
            'faults_by_kind': dict(sorted(self.faults_done.items())),
            'faults_not_applicable': self.handle.not_applicable,
            'commands_sent': values.get('joint_commands', 0),
            'calls_sent': values.get('calls', 0) + values.get('goals', 0),
            'goals_sent': values.get('goals', 0), 'cancels_sent': values.get('cancels', 0),
            'criteria': checks,
            'pass': all(c['pass'] for c in checks.values()),
        }


def level_name(level: bytes | int) -> str:
    value = level[0] if isinstance(level, bytes) else int(level)
    return {DiagnosticStatus.OK[0]: 'OK', DiagnosticStatus.WARN[0]: 'WARN',
            DiagnosticStatus.ERROR[0]: 'ERROR', DiagnosticStatus.STALE[0]: 'STALE'}.get(
                value, str(value))


def service_type(name: str) -> type:
    """``pkg/srv/Name`` -> the generated service class."""
    package, kind, type_name = name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), type_name)


INT_RANGES = {'uint8': (0, 255), 'uint16': (0, 65535), 'uint32': (0, 2**32 - 1),
              'int8': (-128, 127), 'int16': (-32768, 32767), 'int32': (-2**31, 2**31 - 1),
              'octet': (0, 255), 'byte': (0, 255)}


def fill_randomly(message: Any, rng: random.Random) -> None:
    """Absurd-but-typed values in every plain field of a request (nested messages keep their
    defaults, which are empty and so invalid where a driver needs them)."""
    for field, kind in message.get_fields_and_field_types().items():
        if kind in ('double', 'float'):
            value: object = rng.choice((*ABSURD_FLOATS, rng.uniform(-10.0, 10.0)))
        elif kind == 'boolean':
            value = rng.random() < 0.5
        elif kind == 'string':
            value = rng.choice(ABSURD_STRINGS)
        elif kind in INT_RANGES:
            low, high = INT_RANGES[kind]
            value = rng.choice((low, high, rng.randint(low, high)))
        elif kind == 'sequence<string>':
            value = [rng.choice(ABSURD_STRINGS) for _ in range(rng.randrange(4))]
        elif kind == 'sequence<double>':
            value = [rng.choice(ABSURD_FLOATS) for _ in range(rng.randrange(4))]
        else:
            continue
        setattr(message, field, value)


def log_simulator_to(path: Path) -> logging.Handler:
    """The in-process simulators log (keep-alive expiries, malformed frames, ...) to a file
    of their own instead of cluttering the report on stderr."""
    handler = logging.FileHandler(path, encoding='utf-8')
    handler.setFormatter(logging.Formatter('%(asctime)s %(name)s %(levelname)s %(message)s'))
    root = logging.getLogger()
    for old in [h for h in root.handlers if isinstance(h, logging.FileHandler)]:
        root.removeHandler(old)
        old.close()
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    return handler


def run_soak(drivers: list[str], seconds: float, seed: int) -> list[dict[str, object]]:
    targets = soak_targets()
    reports = []
    for name in drivers:
        workdir = Path(tempfile.mkdtemp(prefix=f'gimbal-soak-{name}-'))
        sim_log = Path(tempfile.gettempdir()) / f'{workdir.name}-sim.log'
        log_simulator_to(sim_log)
        try:
            with DomainLease() as domain:
                handle = make_handle(targets[name], workdir)
                try:
                    report = Soak(handle, domain, seconds, seed).run()
                except Exception as exc:  # noqa: BLE001 - report the failure, soak the others
                    report = {'driver': handle.spec.node_name, 'pass': False,
                              'error': f'{type(exc).__name__}: {exc}',
                              'traceback': traceback.format_exc().splitlines()[-8:]}
                report = {'target': name, 'seed': seed, **report, 'sim_log': str(sim_log)}
        finally:
            shutil.rmtree(workdir, ignore_errors=True)
        print(json.dumps(report, indent=2, default=str), flush=True)
        reports.append(report)
    return reports


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    targets = soak_targets()
    parser.add_argument('drivers', nargs='*', default=list(targets),
                        help=f'drivers to soak (default all: {", ".join(targets)})')
    parser.add_argument('--seconds', type=float, default=float(os.environ.get('SOAK_S', 40)),
                        help='soak time per driver (env SOAK_S, default 40)')
    parser.add_argument('--seed', type=int, default=int(os.environ.get('SOAK_SEED', 14)),
                        help='random seed (env SOAK_SEED, default 14)')
    parser.add_argument('--report', type=Path, default=None,
                        help='also write the reports (a JSON list) to this file')
    args = parser.parse_args(argv)
    unknown = [d for d in args.drivers if d not in targets]
    if unknown:
        parser.error(f'unknown driver(s) {unknown}; choose from {list(targets)}')
    print(f'soak: seed {args.seed}, {args.seconds:g} s per driver: {", ".join(args.drivers)}',
          file=sys.stderr, flush=True)
    reports = run_soak(args.drivers, args.seconds, args.seed)
    if args.report is not None:
        args.report.write_text(json.dumps(reports, indent=2, default=str), encoding='utf-8')
    failed = [r['target'] for r in reports if not r.get('pass')]
    summary = {'seed': args.seed, 'seconds_per_driver': args.seconds,
               'passed': [r['target'] for r in reports if r.get('pass')], 'failed': failed}
    print(json.dumps({'summary': summary}), flush=True)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
