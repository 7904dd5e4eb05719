"""The suite's demo: every simulator and driver on this machine, driven through a short script.

Starts each device simulator and its driver node as separate processes (DDS on
loopback, a leased ROS_DOMAIN_ID), drives each through a move, a jog, a preset
and a scan (and the drivers' own extras), prints one live status line per
driver, and ends with a summary. Ctrl-C stops everything cleanly.

Run it with ``make demo`` (which sets up the environment first).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.type_support import check_for_type_support
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_common.registry import DriverSpec, parameter_arguments
from gimbal_driver_testing import (
    DomainLease,
    ManagedProcess,
    find_executable,
    free_tcp_port,
    wait_for,
)
from gimbal_driver_testing.ros import RosTestClient
from gimbal_msgs.action import MoveTo
from gimbal_msgs.srv import GotoPreset, SetPreset, StartScan

ROOT = Path(__file__).resolve().parent.parent
BAG_NAME = 'demo_bag'  # the rosbag2 bag directory in --output
COMMANDS_FILE = 'demo_commands.json'  # what each step commanded (the plot's dashed line)
#: a jog moved the axis when it went this far (rad or m) the commanded way: far below what
#: a 1.5 s jog at the demo's speeds covers (0.3-0.75 rad), far above a report's rounding
JOG_MOVED_MIN = 0.01


@dataclass
class DemoTarget:
    """One registered driver (simulator + node) and the script that drives it."""

    spec: DriverSpec
    scan: StartScan.Request | None = None
    scan_seconds: float = 4.0
    extra_steps: list[tuple[str, Callable[[DemoTarget, RosTestClient], str]]] = field(
        default_factory=list
    )
    port: int = 0
    sim: ManagedProcess | None = None
    node: ManagedProcess | None = None
    step: str = 'starting'
    done: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    latest: JointState | None = None
    diagnostic_level: int = 3
    note: str = ''
    tracebacks: list[str] = field(default_factory=list)
    workdir: Path = Path()
    stop: threading.Event = field(default_factory=threading.Event)
    #: what each step commanded, for the plot (``plot_bag.py``): wall-clock times, as the
    #: recorder stamps the bag
    commands: list[dict[str, Any]] = field(default_factory=list)

    def commanded(self, kind: str, **data: Any) -> None:
        """Note what a step commanded: ``target`` (joint -> position), ``jog`` (joint,
        velocity, t0, t1), ``scan`` (joint -> [low, high], t0, t1), ``home`` or ``keyframes``
        (joint_names, points [(s from t, positions)]). ``t`` defaults to now."""
        self.commands.append({'ns': self.namespace, 'kind': kind, 't': time.time(), **data})

    @property
    def node_name(self) -> str:
        return self.spec.node_name

    @property
    def jog_joint(self) -> str:
        return self.spec.demo.jog_joint or self.spec.joints[0]

    def is_ready(self) -> bool:
        """The simulator accepts connections (its own readiness signal)."""
        from demo_targets import simulator_ready

        return simulator_ready(self)

    @property
    def namespace(self) -> str:
        """Each driver runs in its own namespace so joint_states do not mix."""
        return self.spec.namespace

    def ns(self, name: str) -> str:
        """A private (``~/``) name of the node."""
        return f'{self.namespace}/{self.node_name}/{name}'

    def topic(self, name: str) -> str:
        """A relative topic of the node (joint_states, joint_command)."""
        return f'{self.namespace}/{name}'


class DemoRosClient(RosTestClient):
    """The test client, safe for the demo's one-thread-per-driver use.

    rosidl's generated ``__import_type_support__`` sets a type's ``_TYPE_SUPPORT`` before it
    imports the nested types (an action's SendGoal request, its Goal, ...), so a second
    thread that uses the type in that window sends with a half-loaded type ("Object of type
    'NoneType' is not an instance of 'capsule'"). Loading each type under one lock first
    closes the window.
    """

    _type_lock = threading.Lock()

    def _load(self, kind: type) -> None:
        with self._type_lock:
            check_for_type_support(kind)

    def subscribe(self, topic: str, msg_type: type, reliable: bool = True) -> list[Any]:
        self._load(msg_type)
        return super().subscribe(topic, msg_type, reliable)

    def publish(self, topic: str, msg: Any) -> None:
        self._load(type(msg))
        super().publish(topic, msg)

    def call(self, srv_type: type, name: str, request: Any, timeout: float = 15.0) -> Any:
        self._load(srv_type)
        return super().call(srv_type, name, request, timeout)

    def run_action(self, action_type: type, name: str, goal: Any, timeout: float = 30.0,
                   cancel_after: float | None = None) -> tuple[Any, int, list[Any]]:
        self._load(action_type)
        return super().run_action(action_type, name, goal, timeout, cancel_after)


def available_targets() -> list[DemoTarget]:
    """Every registered driver whose executables are installed."""
    from demo_targets import driver_targets

    targets = driver_targets()
    usable = []
    for target in targets:
        try:
            find_executable(target.spec.package, target.spec.node_executable)
            find_executable(target.spec.package, target.spec.sim_executable)
        except FileNotFoundError:
            continue
        usable.append(target)
    return usable


def run_step(target: DemoTarget, name: str, action: Callable[[], str]) -> None:
    target.step = name
    started = time.time()
    try:
        detail = action()
        target.done.append(f'{name}: {detail}')
    except Exception as exc:  # noqa: BLE001 - the demo reports and goes on
        target.failed.append(f'{name}: {exc}')
        target.tracebacks.append(f'{target.node_name} {name}:\n{traceback.format_exc()}')
    finally:
        target.commanded('step', name=name, t0=started, t1=time.time())


def joint_position(target: DemoTarget, joint: str) -> float:
    """The latest reported position of ``joint`` (NaN before the first joint_states)."""
    latest = target.latest
    if latest is None or joint not in latest.name:
        return math.nan
    return latest.position[list(latest.name).index(joint)]


def settled(target: DemoTarget, joint: str, stop: threading.Event, timeout: float = 10.0,
            window: float = 0.5, band: float = 2e-3) -> float:
    """Wait until ``joint`` stays within ``band`` for ``window`` s; return where it stopped."""
    deadline = time.monotonic() + timeout
    anchor, since = joint_position(target, joint), time.monotonic()
    while not stop.is_set():
        now, position = time.monotonic(), joint_position(target, joint)
        if abs(position - anchor) > band:
            anchor, since = position, now
        elif now - since >= window:
            return position
        if now > deadline:
            raise RuntimeError(f'{joint} still moving after {timeout:g} s (at {position:.3f})')
        stop.wait(0.05)
    return anchor


def drive(target: DemoTarget, ros: RosTestClient, stop: threading.Event) -> None:
    """The per-driver script: move, jog, preset, scan, then the driver's extras. Each step
    checks its effect on joint_states, so OK in the summary means the device did it."""
    goal_joints = list(target.spec.joints[: len(target.spec.move_goal)])

    def move() -> str:
        goal = MoveTo.Goal(joint_names=goal_joints, positions=list(target.spec.move_goal))
        target.commanded('target', positions=dict(zip(goal_joints, goal.positions, strict=True)))
        result, _, feedback = ros.run_action(MoveTo, target.ns('move_to'), goal, timeout=60)
        if not result.success:
            raise RuntimeError(result.message)
        ends = ', '.join(f'{p:.3f}' for p in result.positions)
        return f'reached [{ends}] rad with {len(feedback)} feedback messages'

    def jog() -> str:
        joint, velocity, seconds = target.jog_joint, target.spec.demo.jog_velocity, 1.5
        before = joint_position(target, joint)
        end, first = time.monotonic() + seconds, time.time()
        while time.monotonic() < end and not stop.is_set():
            ros.publish(target.topic('joint_command'),
                        JointState(name=[joint], velocity=[velocity]))
            target.note = f'jog {joint} {joint_position(target, joint) - before:+.3f}'
            stop.wait(0.1)
        target.commanded('jog', joint=joint, velocity=velocity, t0=first, t1=time.time())
        # No more joint_command: the dead-man (command_timeout) must stop the axis.
        try:
            stopped_at = settled(target, joint, stop)
        except RuntimeError as exc:
            raise RuntimeError(f'the dead-man did not stop the jog: {exc}') from None
        target.note = ''
        moved = stopped_at - before
        # "it happens": the axis went the commanded way, well past the position noise. How
        # far is a figure, not a verdict: a jog the dead-man stopped early because the
        # commands reached the node late (a starved machine) moved less, and the node logs
        # that ("took no joint_command for ..."); make bench measures the stream
        if moved * velocity <= 0 or abs(moved) < JOG_MOVED_MIN:
            raise RuntimeError(f'{joint} moved {moved:+.3f} during a {velocity:+g} rad/s jog '
                               f'of {seconds:g} s')
        return (f'{joint} at {velocity:+g} rad/s for {seconds:g} s: moved {moved:+.3f}, '
                f'then stopped by the dead-man at {stopped_at:.3f}')

    def preset() -> str:
        stored = ros.call(SetPreset, target.ns('set_preset'), SetPreset.Request(
            index=1, name='demo', joint_names=goal_joints, positions=list(target.spec.move_goal)))
        if not stored.success:
            raise RuntimeError(stored.message)
        target.commanded('target', positions=dict(zip(goal_joints, target.spec.move_goal,
                                                      strict=True)))
        went = ros.call(GotoPreset, target.ns('goto_preset'), GotoPreset.Request(index=1))
        if not went.success:
            raise RuntimeError(went.message)
        wanted = dict(zip(goal_joints, target.spec.move_goal, strict=True))
        wait_for(lambda: stop.is_set() or all(
            abs(joint_position(target, j) - p) < 0.02 for j, p in wanted.items()), 30,
            f'the joints to reach preset 1 {wanted}')
        settled(target, goal_joints[0], stop, window=0.3)
        return (f'stored preset 1 at the move goal, went back to it from the jog end '
                f'({went.message})')

    def scan() -> str:
        if target.scan is None:
            return 'no scan for this device'
        joint = target.spec.joints[0]
        scan_start = time.time()
        started = ros.call(StartScan, target.ns('start_scan'), target.scan)
        if not started.success:
            raise RuntimeError(started.message)
        low = high = joint_position(target, joint)
        end = time.monotonic() + target.scan_seconds
        while time.monotonic() < end and not stop.is_set():
            position = joint_position(target, joint)
            low, high = min(low, position), max(high, position)
            target.note = f'scan {joint} {low:+.2f}..{high:+.2f}'
            stop.wait(0.05)
        stopped = ros.call(Trigger, target.ns('stop_scan'), Trigger.Request())
        corners = {joint: [target.scan.pan_min, target.scan.pan_max]}
        if len(target.spec.joints) > 1 and target.scan.tilt_max > target.scan.tilt_min:
            corners[target.spec.joints[1]] = [target.scan.tilt_min, target.scan.tilt_max]
        target.commanded('scan', corners=corners, pattern=target.scan.pattern,
                         t0=scan_start, t1=time.time())
        target.note = ''
        if not stopped.success:
            raise RuntimeError(f'stop_scan: {stopped.message}')
        # The sweep may start outside the scan range: count only the part inside it.
        span = target.scan.pan_max - target.scan.pan_min
        covered = min(high, target.scan.pan_max) - max(low, target.scan.pan_min)
        if covered < 0.5 * span:
            raise RuntimeError(f'{joint} only covered {low:.3f}..{high:.3f} of the scan range '
                               f'{target.scan.pan_min:g}..{target.scan.pan_max:g} in '
                               f'{target.scan_seconds:g} s')
        return (f'{started.message}; {joint} covered {low:.2f}..{high:.2f} in '
                f'{target.scan_seconds:g} s, then stop_scan')

    for name, action in (('move', move), ('jog', jog), ('preset', preset), ('scan', scan)):
        if stop.is_set():
            return
        run_step(target, name, action)
    for name, extra in target.extra_steps:
        if stop.is_set():
            return
        run_step(target, name, lambda extra=extra: extra(target, ros))
    target.step = 'done'


LEVELS = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}


def status_line(target: DemoTarget) -> str:
    """One live line: connection level, current step, steps done/failed, joint positions."""
    joints = '-'
    if target.latest is not None:
        joints = ' '.join(f'{n}={p:+.3f}' for n, p in zip(target.latest.name,
                                                          target.latest.position, strict=False))
    progress = f'{len(target.done)} ok' + (f' {len(target.failed)} failed' if target.failed
                                           else '')
    note = f'  {target.note}' if target.note else ''
    return (f'{target.node_name:<22} {LEVELS.get(target.diagnostic_level, "?"):<5} '
            f'{target.step:<10} {progress:<8} {joints}{note}')


class LiveStatus:
    """One line per driver, redrawn in place on a terminal; on a pipe or file, a line per
    driver whenever its step or connection level changes (a log stays readable)."""

    def __init__(self, targets: list[DemoTarget], started: float) -> None:
        self.targets = targets
        self.started = started
        self.live = sys.stdout.isatty()
        self.last: dict[str, tuple[str, int, int]] = {}
        self.drawn = False

    def update(self) -> None:
        if self.live:
            width = shutil.get_terminal_size((120, 24)).columns - 1
            lines = [status_line(t)[:width] for t in self.targets]
            up = f'\x1b[{len(lines)}A' if self.drawn else ''
            sys.stdout.write(up + ''.join(f'\r\x1b[2K{line}\n' for line in lines))
            sys.stdout.flush()
            self.drawn = True
            return
        for target in self.targets:
            key = (target.step, target.diagnostic_level, len(target.failed))
            if self.last.get(target.node_name) != key:
                self.last[target.node_name] = key
                print(f'[{time.monotonic() - self.started:5.1f} s] {status_line(target)}',
                      flush=True)


def start_processes(targets: list[DemoTarget], domain: int, stop: threading.Event) -> None:
    """All simulators first (in parallel), then each node once its simulator is ready."""
    for target in targets:
        target.port = free_tcp_port()
        try:
            target.sim = ManagedProcess.ros(target.spec.package, target.spec.sim_executable, domain,
                                            target.spec.sim_argv(target.workdir, target.port))
        except OSError as exc:
            target.failed.append(f'start: simulator {target.spec.sim_executable}: {exc}')
    for target in targets:
        if target.failed:
            continue
        target.step = 'sim'
        try:
            wait_for(lambda t=target: t.is_ready() or not t.sim.running or stop.is_set(), 30,
                     f'{target.spec.sim_executable} to be ready')
        except TimeoutError as exc:
            target.failed.append(f'start: {exc}')
            continue
        if stop.is_set():
            return
        if not target.sim.running:
            tail = target.sim.output().strip().splitlines()[-3:]
            target.failed.append(f'start: {target.spec.sim_executable} exited: {" / ".join(tail)}')
            continue
        from demo_targets import common_parameters

        params = parameter_arguments({**common_parameters(target),
                                      **target.spec.parameters(target.workdir, target.port),
                                      **target.spec.demo.node_parameters})
        target.node = ManagedProcess.ros(
            target.spec.package, target.spec.node_executable, domain,
            ['--ros-args', '-r', f'__ns:={target.namespace}', *params])
        target.step = 'connect'


def stop_processes(targets: list[DemoTarget], recorder: ManagedProcess | None,
                   output: Path) -> Path | None:
    """Nodes first (they stop their axes while the simulators still listen), then the
    recorder (the bag is finished cleanly), then the simulators; each group in parallel.
    Every process gets SIGINT, then SIGTERM, then SIGKILL (ManagedProcess.stop)."""

    def stop_all(processes: list[ManagedProcess]) -> None:
        threads = [threading.Thread(target=p.stop, name=f'stop-{p.name}') for p in processes]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()

    stop_all([t.node for t in targets if t.node is not None])
    bag = stop_recorder(recorder)
    stop_all([t.sim for t in targets if t.sim is not None])
    for target in targets:
        for process, name in ((target.node, target.node_name),
                              (target.sim, target.spec.sim_executable)):
            if process is not None:
                (output / f'{name}.log').write_text(process.output())
                Path(process.log_path).unlink(missing_ok=True)
    failures = [text for target in targets for text in target.tracebacks]
    if failures:
        (output / 'demo_failures.log').write_text('\n'.join(failures))
    if recorder is not None:
        (output / 'record_bag.log').write_text(recorder.output())
        Path(recorder.log_path).unlink(missing_ok=True)
    return bag


def main() -> int:
    parser = argparse.ArgumentParser(description='Run every simulator and driver of the suite.')
    parser.add_argument('--output', default=str(ROOT / 'demo_output'))
    parser.add_argument('--only', nargs='*', help='node names to run (default: all built)')
    args = parser.parse_args()
    sys.path.insert(0, str(Path(__file__).parent))
    # demo_targets imports this module as `demo`: let it find this one, not a second copy.
    sys.modules.setdefault('demo', sys.modules[__name__])
    output = Path(args.output).resolve()
    targets = available_targets()
    # Only the files an earlier demo wrote are replaced: --output may name any directory.
    # (demo.mcap: the single-file recording of earlier versions.)
    previous = {'demo.mcap', 'positions.png', COMMANDS_FILE, 'demo_failures.log', 'record_bag.log',
                *(f'{t.node_name}.log' for t in targets),
                *(f'{t.spec.sim_executable}.log' for t in targets)}
    output.mkdir(parents=True, exist_ok=True)
    for name in previous:
        (output / name).unlink(missing_ok=True)
    if (output / BAG_NAME).is_dir():
        shutil.rmtree(output / BAG_NAME)  # a rosbag2 bag is never overwritten in place
    if args.only:
        built = [t.node_name for t in targets]
        targets = [t for t in targets if t.node_name in args.only]
        if not targets:
            print(f'demo: none of {args.only} is built; built: {built}', file=sys.stderr)
            return 1
    if not targets:
        print('demo: no driver is built; run make build first', file=sys.stderr)
        return 1
    stop = threading.Event()

    def interrupt(*_: object) -> None:
        if not stop.is_set():
            print('\ndemo: interrupted, stopping everything', flush=True)
        stop.set()

    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    workdir = tempfile.TemporaryDirectory(prefix='gimbal-demo-')
    for target in targets:
        target.workdir = Path(workdir.name)
        target.stop = stop
    lease = DomainLease()
    domain = lease.acquire()
    print(f'demo: {len(targets)} driver(s): {", ".join(t.node_name for t in targets)}')
    print(f'demo: ROS_DOMAIN_ID={domain}, DDS on loopback only; output in {output}', flush=True)
    started = time.monotonic()
    recorder = None
    ros = None
    bag = None
    workers: list[threading.Thread] = []
    try:
        recorder = start_recorder(domain, output)
        start_processes(targets, domain, stop)
        ros = DemoRosClient(domain, 'demo_client')
        watch_topics(ros, targets)
        status = LiveStatus(targets, started)
        deadline = time.monotonic() + 60
        waiting = [t for t in targets if not t.failed]
        while waiting and not stop.is_set():
            status.update()
            for target in list(waiting):
                if target.latest is not None:
                    waiting.remove(target)
                    target.step = 'ready'
                elif not target.node.running:
                    target.failed.append(f'start: {target.spec.node_executable} exited')
                    waiting.remove(target)
                elif time.monotonic() > deadline:
                    target.failed.append(f'start: no {target.topic("joint_states")} in 60 s')
                    waiting.remove(target)
            stop.wait(0.2)
        workers = [threading.Thread(target=drive, args=(t, ros, stop), daemon=True,
                                    name=f'drive-{t.spec.name}')
                   for t in targets if not t.failed]
        for worker in workers:
            worker.start()
        while any(w.is_alive() for w in workers) and not stop.is_set():
            status.update()
            stop.wait(0.5)
        status.update()
    except Exception:  # noqa: BLE001 - report, then clean up below
        traceback.print_exc()
    finally:
        # Stop the drivers before the client goes away, so a blocked step returns.
        if ros is not None:
            for worker in workers:
                worker.join(timeout=0.1 if stop.is_set() else 5.0)
        bag = stop_processes(targets, recorder, output)
        if ros is not None:
            ros.close()
        lease.release()
        workdir.cleanup()
    plot = None
    if bag is not None:
        from plot_bag import plot as plot_bag

        commands = output / COMMANDS_FILE
        commands.write_text(json.dumps([c for t in targets for c in t.commands], indent=1))
        try:
            plot = plot_bag(bag, output / 'positions.png', commands)
        except (SystemExit, Exception) as exc:  # noqa: BLE001 - e.g. a bag cut short
            print(f'demo: no plot from {bag}: {exc}')
    print(summary(targets, output, bag, plot, time.monotonic() - started))
    interrupted = stop.is_set()
    if interrupted:
        print('demo: interrupted; every simulator and node was stopped')
    return 0 if all(not t.failed for t in targets) and not interrupted else 1


def watch_topics(ros: RosTestClient, targets: list[DemoTarget]) -> None:
    """Keep each target's latest joint state and connection level for the status lines."""
    by_node = {t.node_name: t for t in targets}

    def on_diag(array: DiagnosticArray) -> None:
        for status in array.status:
            node, _, part = status.name.partition(': ')
            if node in by_node and part == 'connection':
                by_node[node].diagnostic_level = status.level[0]

    ros.node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, 50)
    for target in targets:
        def keep(msg: JointState, target: DemoTarget = target) -> None:
            target.latest = msg

        ros.node.create_subscription(JointState, target.topic('joint_states'), keep, 10)


def start_recorder(domain: int, output: Path) -> ManagedProcess | None:
    """``scripts/record_bag.py -a``: every topic into a rosbag2 bag (MCAP storage)."""
    recorder = ROOT / 'scripts' / 'record_bag.py'
    if not recorder.exists():
        return None
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    return ManagedProcess([sys.executable, str(recorder), '-a', '-o', str(output / BAG_NAME)],
                          env, name='record_bag')


def stop_recorder(recorder: ManagedProcess | None) -> Path | None:
    """The bag directory, once the recorder has closed it (metadata.yaml written)."""
    if recorder is None:
        return None
    recorder.stop()
    path = Path(recorder.args[-1])
    return path if (path / 'metadata.yaml').is_file() else None


def summary(
    targets: list[DemoTarget], output: Path, bag: Path | None, plot: Path | None, seconds: float
) -> str:
    lines = [f'\ndemo summary ({seconds:.0f} s, {len(targets)} driver(s))']
    for target in targets:
        verdict = 'OK' if not target.failed else 'FAILED'
        if not target.failed and target.step != 'done':
            verdict = f'INTERRUPTED during {target.step}'
        lines.append(f'  {target.spec.title} [{target.node_name}]: {verdict}')
        lines += [f'    done   {d}' for d in target.done]
        lines += [f'    failed {f}' for f in target.failed]
    lines.append(f'  logs: {output}/<node>.log, <simulator>.log, record_bag.log')
    if (output / 'demo_failures.log').exists():
        lines.append(f'  failed steps with tracebacks: {output}/demo_failures.log')
    if bag is not None:
        recorded = ''
        log = output / 'record_bag.log'
        counts = re.findall(r'(\d+ messages on \d+ topics) ->', log.read_text()) \
            if log.exists() else []
        if counts:
            recorded = f'{counts[-1]}; '
        lines.append(f'  bag: {bag} (rosbag2, MCAP storage; {recorded}open with Foxglove, '
                     f'ros2 bag info / ros2 bag play)')
    if plot is not None:
        lines.append(f'  plot: {plot} (commanded vs. actual joint positions per driver)')
    return '\n'.join(lines)


if __name__ == '__main__':
    sys.exit(main())

