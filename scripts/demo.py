"""The suite's demo: every simulator and driver on this machine, driven through a short script.

Starts each device simulator and its driver node as separate processes (DDS on
loopback, a leased ROS_DOMAIN_ID), drives each through a move, a jog, a preset
and a scan (and the drivers' own extras), prints one live status line per
driver, and ends with a summary. Ctrl-C stops everything cleanly.

Run it with ``make demo`` (which sets up the environment first).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_common.ros.testing import RosTestClient
from gimbal_driver_common.testing import (
    DomainLease,
    ManagedProcess,
    find_executable,
    free_tcp_port,
    wait_for,
)
from gimbal_msgs.action import MoveTo
from gimbal_msgs.srv import GotoPreset, SetPreset, StartScan

ROOT = Path(__file__).resolve().parent.parent


@dataclass
class DemoTarget:
    """One simulator + driver pair and the script that drives it."""

    title: str
    package: str
    node_executable: str
    node_name: str
    sim_executable: str
    sim_args: Callable[[DemoTarget], list[str]]
    node_params: Callable[[DemoTarget], list[str]]
    ready_text: str = ''
    joints: tuple[str, ...] = ('pan', 'tilt')
    move_goal: tuple[float, ...] = (0.4, 0.2)
    jog_joint: str = 'pan'
    jog_velocity: float = 0.2
    scan: StartScan.Request | None = None
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

    @property
    def namespace(self) -> str:
        """Each driver runs in its own namespace so joint_states do not mix."""
        return '/' + self.node_name.removesuffix('_driver')

    def ns(self, name: str) -> str:
        """A private (``~/``) name of the node."""
        return f'{self.namespace}/{self.node_name}/{name}'

    def topic(self, name: str) -> str:
        """A relative topic of the node (joint_states, joint_command)."""
        return f'{self.namespace}/{name}'


def virtual_gimbal_target() -> DemoTarget:
    return DemoTarget(
        title='virtual gimbal (reference)',
        package='gimbal_driver_common',
        node_executable='virtual_gimbal_node',
        node_name='virtual_gimbal',
        sim_executable='virtual_gimbal_sim',
        sim_args=lambda t: ['--port', str(t.port)],
        node_params=lambda t: [f'port:={t.port}'],
        ready_text='listening',
        scan=StartScan.Request(pattern='sector', pan_min=-0.3, pan_max=0.3, speed=0.6),
    )


def available_targets() -> list[DemoTarget]:
    """Every target whose executables are built (drivers land one by one)."""
    from demo_targets import driver_targets

    targets = [virtual_gimbal_target(), *driver_targets()]
    usable = []
    for target in targets:
        try:
            find_executable(target.package, target.node_executable)
            find_executable(target.package, target.sim_executable)
        except FileNotFoundError:
            continue
        usable.append(target)
    return usable


def run_step(target: DemoTarget, name: str, action: Callable[[], str]) -> None:
    target.step = name
    try:
        detail = action()
        target.done.append(f'{name}: {detail}')
    except Exception as exc:  # noqa: BLE001 - the demo reports and goes on
        target.failed.append(f'{name}: {exc}')


def drive(target: DemoTarget, ros: RosTestClient, stop: threading.Event) -> None:
    """The per-driver script: move, jog, preset, scan, then the driver's extras."""

    def move() -> str:
        goal = MoveTo.Goal(joint_names=list(target.joints[: len(target.move_goal)]),
                           positions=list(target.move_goal))
        result, _, feedback = ros.run_action(MoveTo, target.ns('move_to'), goal, timeout=60)
        if not result.success:
            raise RuntimeError(result.message)
        ends = ', '.join(f'{p:.3f}' for p in result.positions)
        return f'reached [{ends}] rad with {len(feedback)} feedback messages'

    def jog() -> str:
        end = time.monotonic() + 1.5
        while time.monotonic() < end and not stop.is_set():
            ros.publish(target.topic('joint_command'),
                        JointState(name=[target.jog_joint], velocity=[target.jog_velocity]))
            time.sleep(0.1)
        time.sleep(1.5)  # stop publishing: the dead-man timeout stops the axis
        return f'{target.jog_joint} at {target.jog_velocity} rad/s for 1.5 s, then watchdog stop'

    def preset() -> str:
        stored = ros.call(SetPreset, target.ns('set_preset'),
                          SetPreset.Request(index=1, name='demo', use_current_position=True))
        if not stored.success:
            raise RuntimeError(stored.message)
        went = ros.call(GotoPreset, target.ns('goto_preset'), GotoPreset.Request(index=1))
        if not went.success:
            raise RuntimeError(went.message)
        return 'stored preset 1 at the current position and moved back to it'

    def scan() -> str:
        if target.scan is None:
            return 'no scan for this device'
        started = ros.call(StartScan, target.ns('start_scan'), target.scan)
        if not started.success:
            raise RuntimeError(started.message)
        stop.wait(4.0)
        ros.call(Trigger, target.ns('stop_scan'), Trigger.Request())
        return started.message

    for name, action in (('move', move), ('jog', jog), ('preset', preset), ('scan', scan)):
        if stop.is_set():
            return
        run_step(target, name, action)
    for name, extra in target.extra_steps:
        if stop.is_set():
            return
        run_step(target, name, lambda extra=extra: extra(target, ros))
    target.step = 'done'


def status_line(target: DemoTarget) -> str:
    levels = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}
    joints = '-'
    if target.latest is not None:
        joints = ' '.join(f'{n}={p:+.3f}' for n, p in zip(target.latest.name,
                                                          target.latest.position, strict=False))
    return (f'{target.node_name:<24} {levels.get(target.diagnostic_level, "?"):<5} '
            f'{target.step:<10} {joints}')


def main() -> int:
    parser = argparse.ArgumentParser(description='Run every simulator and driver of the suite.')
    parser.add_argument('--output', default=str(ROOT / 'demo_output'))
    parser.add_argument('--only', nargs='*', help='node names to run (default: all built)')
    args = parser.parse_args()
    sys.path.insert(0, str(Path(__file__).parent))
    output = Path(args.output)
    if output.exists():
        shutil.rmtree(output)
    output.mkdir(parents=True)
    targets = available_targets()
    if args.only:
        targets = [t for t in targets if t.node_name in args.only]
    if not targets:
        print('demo: no driver is built; run make build first', file=sys.stderr)
        return 1
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    lease = DomainLease()
    domain = lease.acquire()
    print(f'demo: ROS_DOMAIN_ID={domain}, DDS on loopback only; output in {output}')
    started = time.monotonic()
    recorder = None
    ros = None
    try:
        for target in targets:
            target.port = free_tcp_port()
            target.sim = ManagedProcess.ros(target.package, target.sim_executable, domain,
                                            target.sim_args(target))
            if target.ready_text:
                target.sim.wait_for_output(target.ready_text, timeout=30)
            params = [x for p in target.node_params(target) for x in ('-p', p)]
            target.node = ManagedProcess.ros(
                target.package, target.node_executable, domain,
                ['--ros-args', '-r', f'__ns:={target.namespace}', *params])
        ros = RosTestClient(domain, 'demo_client')
        recorder = start_recorder(domain, output)
        watch_topics(ros, targets)
        for target in targets:
            try:
                wait_for(lambda t=target: t.latest is not None or stop.is_set(), 60,
                         f'{target.node_name} joint_states')
            except TimeoutError as exc:
                target.failed.append(f'start: {exc}')
        workers = [threading.Thread(target=drive, args=(t, ros, stop), daemon=True)
                   for t in targets if not t.failed]
        for worker in workers:
            worker.start()
        live = sys.stdout.isatty()
        while any(w.is_alive() for w in workers) and not stop.is_set():
            lines = [status_line(t) for t in targets]
            if live:
                sys.stdout.write('\x1b[2K' + '\n\x1b[2K'.join(lines) + f'\x1b[{len(lines)}A\r')
            else:
                print(' | '.join(lines), flush=True)
            time.sleep(0.5 if live else 2.0)
        if live:
            sys.stdout.write('\n' * len(targets))
    except Exception:  # noqa: BLE001 - report, then clean up below
        traceback.print_exc()
    finally:
        if stop.is_set():
            print('\ndemo: interrupted, stopping everything')
        bag = stop_recorder(recorder)
        if ros is not None:
            ros.close()
        for target in targets:
            for process in (target.node, target.sim):
                if process is not None:
                    process.stop()
            if target.node is not None:
                (output / f'{target.node_name}.log').write_text(target.node.output())
        lease.release()
    plot = None
    if bag is not None:
        from plot_bag import plot as plot_bag

        try:
            plot = plot_bag(bag, output / 'positions.png')
        except (SystemExit, ValueError, OSError) as exc:
            print(f'demo: no plot: {exc}')
    print(summary(targets, output, bag, plot, time.monotonic() - started))
    return 0 if all(not t.failed for t in targets) and not stop.is_set() else 1


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
    recorder = ROOT / 'scripts' / 'record_bag.py'
    if not recorder.exists():
        return None
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    return ManagedProcess([sys.executable, str(recorder), str(output / 'demo.mcap')], env,
                          name='record_bag')


def stop_recorder(recorder: ManagedProcess | None) -> Path | None:
    if recorder is None:
        return None
    recorder.stop()
    path = Path(recorder.args[-1])
    return path if path.exists() else None


def summary(
    targets: list[DemoTarget], output: Path, bag: Path | None, plot: Path | None, seconds: float
) -> str:
    lines = [f'\ndemo summary ({seconds:.0f} s, {len(targets)} driver(s))']
    for target in targets:
        verdict = 'OK' if not target.failed else 'FAILED'
        lines.append(f'  {target.title} [{target.node_name}]: {verdict}')
        lines += [f'    done   {d}' for d in target.done]
        lines += [f'    failed {f}' for f in target.failed]
    lines.append(f'  node logs: {output}/<node>.log')
    if bag is not None:
        lines.append(f'  bag: {bag} (open with Foxglove Studio or ros2 bag info)')
    if plot is not None:
        lines.append(f'  plot: {plot} (commanded vs. actual joint positions per driver)')
    return '\n'.join(lines)


if __name__ == '__main__':
    sys.exit(main())

