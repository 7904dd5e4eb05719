"""Scale benchmark: N driver nodes against N simulators beside N bare rclpy nodes.

``python bench/scale.py virtual_gimbal --nodes 1 8 --seconds 30 --repeats 3``

Each of the N pairs has a ROS domain of its own (N independent rigs): one driver node at
its registered in-process simulator (``spec.sim_handle``, run in this process) and its
bench ``publish_rate`` (50 Hz), one bare rclpy node (``reference_publisher.py``:
``rclpy.spin``, the default executor, a timer publishing the same two-joint JointState at
the same rate) and one probe subscribed to both, so each publisher has one subscriber.
The 2N node processes run at once; every window measures all of them together (the
kernel's per-process CPU clock, ``harness.cpu_percents``), so the driver/bare ratio of a
window compares processes that saw the same machine. PSS (``/proc/<pid>/smaps_rollup``)
is read at the end of each window. With ``--threads`` the drivers' CPU is split per
thread name (``BENCH_THREAD_CPU_DIR``: the node hook writes each node's thread names, and
``/proc/<pid>/task/*`` gives each thread's ticks; ``native`` is DDS and rcl).

The point's figure is the median over ``--repeats`` windows of the per-window ratio
(sum of the drivers' CPU / sum of the bare nodes' CPU), with its min and max; beside it
the same per message received (``cpu_per_message_ratio``): on a loaded machine a driver
whose in-process simulator waits for a core publishes below its rate, and spends less.
With ``--baseline-src DIR`` (``git archive REV src | tar -x -C DIR``) each rig also runs
the driver of that revision against a simulator of its own, in the same windows
(``driver_vs_baseline_cpu``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from driver_bench import cpu_by_thread, start_node  # noqa: E402
from harness import (  # noqa: E402
    ROOT,
    JointStateProbe,
    ProbeClient,
    cpu_percents,
    git_revision,
    thread_cpu_seconds,
)

from gimbal_driver_common.registry import drivers  # noqa: E402
from gimbal_driver_common.sim_handle import make_handle  # noqa: E402
from gimbal_driver_testing import DomainLease, ManagedProcess, ros_env, wait_for  # noqa: E402


def pss_mb(pid: int) -> float:
    """Proportional set size of a process, MB (shared pages split among their users)."""
    for line in Path(f'/proc/{pid}/smaps_rollup').read_text().splitlines():
        if line.startswith('Pss:'):
            return round(int(line.split()[1]) / 1024.0, 1)
    return 0.0


class Pair:
    """One rig: a driver node at its simulator, a bare rclpy node, a probe on both."""

    def __init__(self, spec, workdir: Path, rate_hz: float,
                 baseline: list[str] | None = None) -> None:
        self.lease = DomainLease()
        domain = self.lease.acquire()
        self.handle, self.node = self._driver(spec, workdir, rate_hz, domain)
        self.baseline: Baseline | None = None
        if baseline:
            self.baseline = Baseline(spec, workdir, rate_hz, baseline)
        self.bare = ManagedProcess(
            [sys.executable, str(ROOT / 'bench' / 'reference_publisher.py'), str(rate_hz)],
            ros_env(domain), name='reference_publisher')
        self.probe = ProbeClient(domain, f'bench_scale_{domain}')
        self.states = JointStateProbe(self.probe)
        self.bare_states = JointStateProbe(self.probe, 'reference_joint_states')

    @staticmethod
    def _driver(spec, workdir: Path, rate_hz: float, domain: int):
        handle = make_handle(spec, workdir)
        handle.start()
        parameters = {**handle.node_parameters(),
                      'presets_file': str(workdir / 'presets.yaml'), 'publish_rate': rate_hz}
        return handle, start_node(domain, spec.package, parameters,
                                  executable=spec.node_executable)

    def wait_ready(self, timeout: float) -> None:
        wait_for(lambda: len(self.states.arrivals) > 10 and len(self.bare_states.arrivals) > 10,
                 timeout, 'joint_states from the driver node and the bare node')
        if self.baseline is not None:
            wait_for(lambda: len(self.baseline.states.arrivals) > 10, timeout,
                     'joint_states from the baseline driver node')

    def close(self) -> None:
        for step in (self.probe.close, lambda: self.node.stop(timeout=5.0), self.bare.stop,
                     self.handle.stop, self.lease.release):
            with contextlib.suppress(Exception):
                step()
        if self.baseline is not None:
            self.baseline.close()


class Baseline:
    """The same driver from other sources (``--baseline-src``: an older revision's
    ``src/<pkg>/`` directories first on the node's PYTHONPATH), in a domain of its own, so
    a change is measured against what it changed in one window."""

    def __init__(self, spec, workdir: Path, rate_hz: float, paths: list[str]) -> None:
        self.lease = DomainLease()
        domain = self.lease.acquire()
        path = Path(workdir, 'baseline')
        path.mkdir()
        saved = os.environ.get('PYTHONPATH', '')
        os.environ['PYTHONPATH'] = os.pathsep.join([*paths, saved])
        try:
            self.handle, self.node = Pair._driver(spec, path, rate_hz, domain)
        finally:
            os.environ['PYTHONPATH'] = saved
        self.probe = ProbeClient(domain, f'bench_scale_baseline_{domain}')
        self.states = JointStateProbe(self.probe)

    def close(self) -> None:
        for step in (self.probe.close, lambda: self.node.stop(timeout=5.0), self.handle.stop,
                     self.lease.release):
            with contextlib.suppress(Exception):
                step()


def rate(probe: JointStateProbe, start: float, end: float) -> float:
    with probe._lock:
        count = sum(1 for arrival, _, _ in probe.arrivals if start <= arrival <= end)
    return count / (end - start)


def measure(pairs: list[Pair], seconds: float, threads: bool) -> dict:
    """One window over every node process at once."""
    drivers_ = [pair.node.process.pid for pair in pairs]
    bares = [pair.bare.process.pid for pair in pairs]
    baselines = [pair.baseline.node.process.pid for pair in pairs if pair.baseline]
    before = {pid: thread_cpu_seconds(pid) for pid in drivers_} if threads else {}
    start = time.time()
    cpu = cpu_percents(drivers_ + bares + baselines, seconds)
    end = time.time()
    n = len(pairs)
    driver_cpu, bare_cpu, baseline_cpu = cpu[:n], cpu[n:2 * n], cpu[2 * n:]
    window: dict = {}
    if baselines:
        window.update({
            'baseline_cpu_percent': baseline_cpu,
            'baseline_cpu_ratio': round(sum(baseline_cpu) / max(sum(bare_cpu), 1e-9), 3),
            'driver_vs_baseline_cpu': round(sum(driver_cpu) / max(sum(baseline_cpu), 1e-9), 3),
            'baseline_pss_mb': [pss_mb(pid) for pid in baselines],
            'baseline_hz': [round(rate(p.baseline.states, start, end), 1)
                            for p in pairs if p.baseline],
        })
    window.update({
        'driver_cpu_percent': driver_cpu,
        'bare_cpu_percent': bare_cpu,
        'cpu_ratio': round(sum(driver_cpu) / max(sum(bare_cpu), 1e-9), 3),
        'driver_pss_mb': [pss_mb(pid) for pid in drivers_],
        'bare_pss_mb': [pss_mb(pid) for pid in bares],
        'driver_hz': [round(rate(p.states, start, end), 1) for p in pairs],
        'bare_hz': [round(rate(p.bare_states, start, end), 1) for p in pairs],
    })
    # CPU per message published: a node that falls behind its rate (a loaded machine, a
    # simulator in this process waiting for a core) spends less for fewer messages
    per_message = [cpu / max(hz, 1e-9) for cpu, hz in zip(
        driver_cpu + bare_cpu, window['driver_hz'] + window['bare_hz'], strict=True)]
    window['cpu_per_message_ratio'] = round(sum(per_message[:n]) / sum(per_message[n:]), 3)
    window['pss_ratio'] = round(sum(window['driver_pss_mb']) / sum(window['bare_pss_mb']), 3)
    if threads:
        wall = end - start
        split: dict[str, float] = {}
        for pid in drivers_:
            for name, share in cpu_by_thread(pid, before[pid], wall).items():
                split[name] = split.get(name, 0.0) + share / n
        window['driver_cpu_by_thread_per_node'] = {
            k: round(v, 2) for k, v in sorted(split.items(), key=lambda kv: -kv[1])}
    return window


def spread(values: list[float]) -> dict[str, float]:
    return {'median': round(statistics.median(values), 3), 'min': round(min(values), 3),
            'max': round(max(values), 3)}


def run_point(spec, n: int, seconds: float, repeats: int, rate_hz: float,
              threads: bool, baseline: list[str] | None = None) -> dict:
    with tempfile.TemporaryDirectory(prefix=f'scale-{spec.name}-') as workdir:
        pairs: list[Pair] = []
        try:
            for index in range(n):
                path = Path(workdir, str(index))
                path.mkdir()
                pairs.append(Pair(spec, path, rate_hz, baseline))
            for pair in pairs:
                pair.wait_ready(60.0)
            time.sleep(3.0)  # discovery and start-up transients
            windows = [measure(pairs, seconds, threads) for _ in range(repeats)]
        finally:
            for pair in pairs:
                pair.close()
    per_node = lambda key: [statistics.mean(w[key]) for w in windows]  # noqa: E731
    compared = {}
    if baseline:
        compared = {
            'baseline_cpu_ratio': spread([w['baseline_cpu_ratio'] for w in windows]),
            'driver_vs_baseline_cpu': spread([w['driver_vs_baseline_cpu'] for w in windows]),
            'baseline_pss_mb_per_node': spread(per_node('baseline_pss_mb')),
        }
    return {**compared,
        'nodes': n, 'seconds_per_window': seconds, 'windows': windows,
        'cpu_ratio': spread([w['cpu_ratio'] for w in windows]),
        'cpu_per_message_ratio': spread([w['cpu_per_message_ratio'] for w in windows]),
        'driver_hz': spread(per_node('driver_hz')),
        'bare_hz': spread(per_node('bare_hz')),
        'pss_ratio': spread([w['pss_ratio'] for w in windows]),
        'driver_cpu_percent_per_node': spread(per_node('driver_cpu_percent')),
        'bare_cpu_percent_per_node': spread(per_node('bare_cpu_percent')),
        'driver_pss_mb_per_node': spread(per_node('driver_pss_mb')),
        'bare_pss_mb_per_node': spread(per_node('bare_pss_mb')),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    registered = {spec.name: spec for spec in drivers()}
    parser.add_argument('names', nargs='*', help=f'subset of {list(registered)}')
    parser.add_argument('--nodes', type=int, nargs='+', default=[1, 8])
    parser.add_argument('--seconds', type=float, default=30.0)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--threads', action='store_true', help='split driver CPU per thread')
    parser.add_argument('--baseline-src', type=Path, default=None,
                        help='a tree with src/<pkg>/ of another revision (git archive): its '
                             'driver runs beside, against a simulator of its own')
    parser.add_argument('--output', type=Path, default=ROOT / 'bench_output' / 'scale.json')
    args = parser.parse_args()
    if args.threads and not os.environ.get('BENCH_THREAD_CPU_DIR'):
        os.environ['BENCH_THREAD_CPU_DIR'] = tempfile.mkdtemp(prefix='scale-threads-')
    results: dict = {'revision': git_revision(), 'date': time.strftime('%Y-%m-%dT%H:%M:%S'),
                     'load_average_before': Path('/proc/loadavg').read_text().split()[:3]}
    for name in args.names or list(registered):
        spec = registered[name]
        results[name] = {}
        for n in args.nodes:
            print(f'scale: {name} N={n} ...', file=sys.stderr, flush=True)
            baseline = ([str(path) for path in sorted((args.baseline_src / 'src').iterdir())]
                        if args.baseline_src else None)
            point = run_point(spec, n, args.seconds, args.repeats, spec.bench.publish_rate,
                              args.threads, baseline)
            results[name][str(n)] = point
            print(json.dumps({k: v for k, v in point.items() if k != 'windows'}),
                  file=sys.stderr, flush=True)
    results['load_average_after'] = Path('/proc/loadavg').read_text().split()[:3]
    args.output.parent.mkdir(exist_ok=True)
    args.output.write_text(json.dumps(results, indent=1))
    print(json.dumps(results, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
