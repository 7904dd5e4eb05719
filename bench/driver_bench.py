"""Shared steps of the per-driver benchmarks (bench_<driver>.py): codec rates and node figures.

Every driver benchmark runs its simulator inside the bench process (so a
:class:`~command_stream.DeviceRecorder` can watch the device model) and the driver node
as a separate process, then measures, in this order and on one node process:

1. ``cpu_percent`` of the node while it publishes at ``publish_rate``, the
   ``sim_to_subscriber`` latency of the joint_states received meanwhile
   and the ``joint_states_hz`` achieved in the same window;
2. ``command_stream``: a steady joint_command stream at 50 and 100 Hz against the
   simulator, next to a bare rclpy reference fed by the same stream
   (:mod:`command_stream`), then ``move_and_stop``: a ~/move_to goal to its first device
   bytes and ~/stop answered while the move runs.

While the node runs, this process' GIL switch interval is lowered (see
``BENCH_SWITCH_INTERVAL_S``) so the in-process simulator answers like a device would.
"""

from __future__ import annotations

import contextlib
import json
import os
import struct
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from command_stream import (
    DeviceRecorder,
    StreamSpec,
    move_and_stop_figures,
    stop_during_stream_figures,
    stream_figures,
    trace_figures,
)
from harness import (
    ROOT,
    JointStateProbe,
    ProbeClient,
    cpu_percents,
    percentiles,
    reference_publisher,
    thread_cpu_seconds,
    wire_limit_frames_per_s,
)

from gimbal_driver_common.registry import DriverSpec, parameter_arguments
from gimbal_driver_common.sim_handle import make_handle
from gimbal_driver_testing import ManagedProcess, wait_for

# Bytes a TCP segment adds to its payload on 100BASE-TX Ethernet: preamble+SFD 8, MAC header
# 14, FCS 4, inter-frame gap 12, IPv4 20, TCP 20 (no options). One frame per segment (the
# drivers set TCP_NODELAY and exchange one request/reply at a time), and a minimum Ethernet
# frame of 64 bytes (MAC header through FCS).
ETHERNET_WIRE_OVERHEAD = 8 + 12
ETHERNET_MIN_FRAME = 64
TCP_IP_HEADERS = 20 + 20
MAC_HEADER_AND_FCS = 14 + 4

# The simulator runs in the bench process next to the subscriber's executor threads; a real
# device answers on its own hardware. With CPython's default 5 ms GIL switch interval a
# simulator thread woken by a request can wait that long behind a probe callback, so each of a
# polled driver's request/reply round trips could pick up a bench-made delay. The node process
# is not affected by this setting.
BENCH_SWITCH_INTERVAL_S = 0.0002

def tcp_wire_limit_frames_per_s(frame_bytes: int, bits_per_second: float = 100e6) -> float:
    """Frames per second a TCP link carries, one protocol frame per Ethernet frame."""
    ethernet = max(ETHERNET_MIN_FRAME, MAC_HEADER_AND_FCS + TCP_IP_HEADERS + frame_bytes)
    return wire_limit_frames_per_s(ethernet + ETHERNET_WIRE_OVERHEAD, bits_per_second,
                                   bits_per_byte=8)


def cpu_rate(operation: Callable[[], object], cpu_seconds: float = 1.0,
             warm_up_s: float = 0.1) -> float:
    """Calls per second of this thread's CPU time: frames/s on one core, whatever else runs.

    ``harness.rate`` divides by wall time, which on a machine shared with other processes
    counts the time this thread waited for a core; the codec figure is per CPU-second.
    """
    warm_up = time.thread_time() + warm_up_s   # caches, allocator and branch predictors
    while time.thread_time() < warm_up:
        operation()
    count = 0
    start = time.thread_time()
    while True:
        for _ in range(200):
            operation()
        count += 200
        used = time.thread_time() - start
        if used >= cpu_seconds:
            return count / used


#: the codec's decode rate is at least this fraction of the machine reference's
#: (:func:`machine_decode_rate`, same frame size, same run): within 20x the CPU of the least
#: a Python decoder does with the frame. It replaces "100,000 frames/s", set on one machine
#: (the reference read 1.1-2.5 million frames/s on the 2-core machines since).
CODEC_RATIO_TARGET = 0.05

#: rounds of the interleaved codec measurement (:func:`codec_figures`)
CODEC_ROUNDS = 5


def codec_figures(frame: str, frame_bytes: int, encode: Callable[[], object],
                  decode: Callable[[], object], wire: str, wire_limit: float,
                  seconds: float = 1.0, **extra: object) -> dict:
    """Encode/decode rate of one frame on one core, next to the wire's frame limit and to
    this machine's own reference decode of a frame of that size (:func:`machine_decoder`).

    The three are measured in ``CODEC_ROUNDS`` interleaved rounds and each keeps its best
    round, so a minute in which the machine ran slower (another process's cache traffic,
    frequency) lowers codec and reference alike instead of the one measured then: measured
    one after the other, the same decoder's ratio moved 0.055-0.079 between three runs.
    """
    reference = machine_decoder(frame_bytes)
    share = seconds / CODEC_ROUNDS
    best = {'encode': 0.0, 'decode': 0.0, 'machine': 0.0}
    for index in range(CODEC_ROUNDS):
        warm_up = 0.1 if index == 0 else 0.01
        for name, operation in (('encode', encode), ('decode', decode),
                                ('machine', reference)):
            best[name] = max(best[name], cpu_rate(operation, share, warm_up))
    return {
        'clock': 'thread CPU time (frames per CPU-second of one core), best of '
                 f'{CODEC_ROUNDS} interleaved rounds',
        'frame': frame,
        'frame_bytes': frame_bytes,
        'encode_frames_per_s': round(best['encode']),
        'decode_frames_per_s': round(best['decode']),
        'wire': wire,
        'wire_limit_frames_per_s': round(wire_limit, 1),
        'machine_reference_frames_per_s': round(best['machine']),
        'decode_vs_machine_reference': round(best['decode'] / best['machine'], 3),
        **extra,
    }


def machine_decoder(frame_bytes: int) -> Callable[[], object]:
    """The least a Python decoder does with a frame of ``frame_bytes``: ``struct.unpack`` of
    its bytes into a tuple, then a dict of two fields. Its rate, measured in the same run,
    is the codec's reference on any machine (``CODEC_RATIO_TARGET``)."""
    layout = struct.Struct(f'<{frame_bytes}B')
    frame = bytes(i % 256 for i in range(frame_bytes))

    def decode() -> object:
        values = layout.unpack(frame)
        return {'kind': values[0], 'payload': values[1:]}

    return decode


def start_node(domain: int, package: str, parameters: dict[str, object],
               params_file: bool = True, executable: str = '',
               namespace: str = '') -> ManagedProcess:
    """``<package>_node`` (or ``executable``) with its simulator YAML (if any) and
    ``parameters`` on top, in ``namespace`` if given."""
    args = ['--ros-args']
    config = ROOT / 'src' / package / 'config' / f'{package}_sim.yaml'
    if params_file and Path(config).is_file():
        args += ['--params-file', str(config)]
    if namespace:
        args += ['-r', f'__ns:={namespace}']
    return ManagedProcess.ros(package, executable or f'{package}_node', domain,
                              args + parameter_arguments(parameters), extra_env=node_hook_env())


#: bench/node_hook/sitecustomize.py instruments the node process when one of these is set
NODE_HOOK_VARIABLES = ('BENCH_TRACE_DIR', 'BENCH_EXECUTOR', 'BENCH_SWITCH_INTERVAL_S',
                       'BENCH_THREAD_CPU_DIR')


def node_hook_env() -> dict[str, str] | None:
    """PYTHONPATH with bench/node_hook first, when a node hook variable asks for it."""
    if not any(os.environ.get(name) for name in NODE_HOOK_VARIABLES):
        return None
    paths = [str(ROOT / 'bench' / 'node_hook'), os.environ.get('PYTHONPATH', '')]
    return {'PYTHONPATH': os.pathsep.join(p for p in paths if p)}


def cpu_by_thread(pid: int, before: dict[int, float], wall: float) -> dict[str, float]:
    """The node's CPU over the window (% of a core) per Python thread name (node hook's
    ``threads_<pid>.json``); threads without one (DDS, rcl) are summed as ``native``."""
    after = thread_cpu_seconds(pid)
    path = Path(os.environ['BENCH_THREAD_CPU_DIR'], f'threads_{pid}.json')
    names = {int(k): v for k, v in json.loads(path.read_text()).items()} if path.exists() \
        else {}
    shares: dict[str, float] = {}
    for tid, seconds in after.items():
        name = names.get(tid, 'native').rstrip('0123456789_-') or 'native'
        shares[name] = shares.get(name, 0.0) + 100.0 * (seconds - before.get(tid, 0.0)) / wall
    return {name: round(share, 2) for name, share in sorted(shares.items(),
                                                           key=lambda kv: -kv[1])}


def node_figures(
    domain: int,
    package: str,
    parameters: dict[str, object],
    stream: StreamSpec | None = None,
    recorder: DeviceRecorder | None = None,
    window_seconds: float = 10.0,
    settle_seconds: float = 2.0,
    startup_timeout: float = 40.0,
    observe: Callable[[float, float], dict] | None = None,
    executable: str = '',
    cpu_reference: bool = True,
) -> dict:
    """Start the node; in one window CPU, joint_states rate and latency; then commands.

    With ``cpu_reference`` the bare rclpy publisher runs at the node's ``publish_rate``
    during that window and its CPU is measured beside the node's (not for the windows
    that poll flat out: a 1000 Hz reference would take the CPU the node is measured on).

    ``observe(start, end)`` (monotonic times of the window) may add simulator-side figures.
    """
    results: dict = {'publish_rate': parameters.get('publish_rate'),
                     'cpu_publish_rate': parameters.get('publish_rate'),
                     'bench_gil_switch_interval_ms': BENCH_SWITCH_INTERVAL_S * 1e3}
    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(BENCH_SWITCH_INTERVAL_S)
    node = start_node(domain, package, parameters, executable=executable)
    try:
        with ProbeClient(domain, f'bench_{package}') as ros:
            states = JointStateProbe(ros)
            try:
                wait_for(lambda: len(states.arrivals) > 10, startup_timeout,
                         f'joint_states from {package}_node')
            except TimeoutError as exc:
                raise RuntimeError(f'{exc}; node output:\n{node.output()[-2000:]}') from exc
            # the bare rclpy publisher at the node's rate runs beside the node, so both CPU
            # figures come from one window of the same machine
            reference_rate = parameters.get('publish_rate') if cpu_reference else None
            with (reference_publisher(ros, domain, float(reference_rate)) if reference_rate
                  else contextlib.nullcontext((None, None))) as (reference, beside):
                # let the start-up transient pass (DDS discovery of this subscriber slows
                # the node and the simulator for a second or two on a loaded machine)
                time.sleep(settle_seconds)
                states.clear()
                # one window: CPU of the node and the reference, and the joint_states
                # received meanwhile
                start, start_wall = time.monotonic(), time.time()
                pids = [node.process.pid] + ([reference.process.pid] if reference else [])
                threads_before = thread_cpu_seconds(node.process.pid)
                cpu = cpu_percents(pids, window_seconds)
                end, end_wall = time.monotonic(), time.time()
                if os.environ.get('BENCH_THREAD_CPU_DIR'):
                    results['node_cpu_by_thread'] = cpu_by_thread(
                        node.process.pid, threads_before, end - start)
                results['cpu_percent'] = cpu[0]
                if reference:
                    results['rclpy_publisher_cpu_percent_at_publish_rate'] = cpu[1]
                    # the bare pair's latency in the same window, to the same subscriber
                    results['rclpy_pubsub_beside'] = percentiles(
                        beside.stamp_latencies(start_wall, end_wall))
                    # the rate a user's own node reaches on this machine in this window:
                    # a rate target is a ratio to it (RATE_RATIO_TARGET)
                    results['rclpy_publisher_hz_beside'] = stamped_rate(
                        beside, start_wall, end_wall)
            if observe is not None:
                results.update(observe(start, end))
            results['joint_states_hz'] = received_rate(states)
            results['joint_states_stamped_in_window_hz'] = stamped_rate(
                states, start_wall, end_wall)
            results['sim_to_subscriber'] = percentiles(states.stamp_latencies())
            results.update(report_freshness(states))
            if stream is not None and recorder is not None:
                try:
                    results['command_stream'] = stream_figures(domain, stream, recorder,
                                                               node_pid=node.process.pid)
                except (RuntimeError, TimeoutError) as exc:
                    raise RuntimeError(f'{exc}; node exit code {node.process.poll()}, output:\n'
                                       f'{node.output()[-3000:]}') from exc
                results['move_and_stop'] = move_and_stop_figures(ros, stream, recorder)
                if 'stopped' in recorder.events:
                    results['stop_during_stream'] = stop_during_stream_figures(
                        ros, domain, stream, recorder)
                results['stream_variant'] = {name: os.environ[name] for name in
                                             NODE_HOOK_VARIABLES if os.environ.get(name)}
    finally:
        sys.setswitchinterval(switch_interval)
        code = node.stop(timeout=5.0)   # a clean shutdown takes ~1 s; bound the bench time
        if os.environ.get('BENCH_TRACE_DIR') and stream is not None:
            results['node_trace'] = trace_figures(Path(os.environ['BENCH_TRACE_DIR']),
                                                  node.process.pid)
        if code not in (0, -2, 130):
            add_note(results, f'node exited with code {code} (-9: still running 5 s after '
                     'SIGINT and 3 s after SIGTERM, killed)')
    return results


def received_rate(states: JointStateProbe) -> float:
    """Messages per second over the recorded arrivals (first to last)."""
    with states._lock:
        times = [arrival for arrival, _, _ in states.arrivals]
    if len(times) < 2:
        return 0.0
    return round((len(times) - 1) / (times[-1] - times[0]), 1)


def stamped_rate(states: JointStateProbe, start: float, end: float) -> float:
    """Distinct samples per second whose stamps (wall time) fall in the window: the node's
    own publication rate there, whatever the delivery did before or after (beside
    :func:`received_rate`, which spans the first to the last arrival)."""
    with states._lock:
        stamps = {stamp for _, stamp, _ in states.arrivals if start <= stamp <= end}
    return round(len(stamps) / max(end - start, 1e-9), 1)


def report_freshness(states: JointStateProbe) -> dict:
    """How often the device data behind joint_states changes, and the latency of its first
    publication: a polled driver republishes a held report until the next one arrives."""
    with states._lock:
        arrivals = list(states.arrivals)
    first: dict[float, float] = {}
    for arrival, stamp, _ in arrivals:
        if stamp > 0 and stamp not in first:
            first[stamp] = arrival
    if len(first) < 2:
        return {}
    stamps = sorted(first)
    return {
        'device_reports_hz': round((len(stamps) - 1) / (stamps[-1] - stamps[0]), 1),
        'sim_to_subscriber_first_publication': percentiles(
            [first[s] - s for s in stamps]),
    }


def add_note(results: dict, note: str) -> None:
    results.setdefault('notes', []).append(note)


def explain_latency(results: dict, cause: str, label: str = '') -> None:
    """A note when sim_to_subscriber p99 is over 5 ms (the figure first set on one machine;
    the target is a ratio to the same run's rclpy pub/sub p99): the driver's structural
    cause, then the share of the machine (the same run's rclpy reference shows it)."""
    latency = results.get('sim_to_subscriber', {})
    if latency.get('p99_ms', 0.0) < 5.0:
        return
    first = results.get('sim_to_subscriber_first_publication', {})
    where = f' at {label}' if label else ''
    add_note(results, (
        f'sim_to_subscriber{where} p50/p99 {latency["p50_ms"]}/{latency["p99_ms"]} ms is over '
        f'5 ms (first publication of each device report: {first.get("p50_ms")}/'
        f'{first.get("p99_ms")} ms; device reports {results.get("device_reports_hz")} Hz). '
        f'{cause} What exceeds that is scheduling delay on a machine shared with other '
        'processes: compare the bare rclpy pub/sub p99 of the same run (reference).'))


def rate_vs_publisher_beside(figures: dict) -> float | None:
    """joint_states published in the window against the bare rclpy publisher's rate at
    the same ``publish_rate`` beside it (:func:`node_figures`): what the driver reaches
    against what a user's own node reaches on this machine at the same moment."""
    reference = figures.get('rclpy_publisher_hz_beside')
    achieved = figures.get('joint_states_stamped_in_window_hz')
    if not reference or achieved is None:
        return None
    return round(achieved / reference, 3)


def check_targets(results: dict, rate_ratio_target: float | None = None) -> None:
    """``results['targets']``: each target (bench/README.md, "Targets") with the measured
    value, met or not, and the margin (positive = better than the target). The
    ``sim_to_subscriber`` p99 and CPU targets are ratios to the same run's rclpy references,
    added with them (``run.py``); the codec's is a ratio to the machine reference decode
    measured beside it (``CODEC_RATIO_TARGET``); a rate's (``rate_ratio_target``) a ratio
    to the bare publisher's rate beside the node (``joint_states_vs_rclpy_publisher``)."""
    checks: dict[str, tuple[float | None, float, bool]] = {
        f'codec decode >= {CODEC_RATIO_TARGET:g}x the machine reference decode of the run': (
            results.get('codec', {}).get('decode_vs_machine_reference'), CODEC_RATIO_TARGET,
            True),
    }
    if rate_ratio_target is not None:
        checks[f'joint_states >= {rate_ratio_target:g}x the rclpy publisher beside it at '
               f'{results.get("publish_rate"):g} Hz'] = (
            results.get('joint_states_vs_rclpy_publisher'), rate_ratio_target, True)
    targets = {}
    for name, (measured, limit, higher_is_better) in checks.items():
        if measured is None:
            continue
        margin = measured - limit if higher_is_better else limit - measured
        met = margin >= 0 if higher_is_better else margin > 0
        targets[name] = {'measured': measured, 'met': met, 'margin': round(margin, 3)}
    results['targets'] = targets


def explain_streamed_rate(results: dict, source: str) -> None:
    """A STREAMED node publishes each new device sample (at most publish_rate), so its
    joint_states rate is the device's report rate: a note when that is below publish_rate."""
    achieved, rate = results.get('joint_states_hz', 0.0), results.get('publish_rate') or 0.0
    if achieved < 0.95 * rate:
        add_note(results, (
            f'joint_states {achieved} Hz at publish_rate {rate:g}: the node publishes each new '
            f'device sample as it arrives (publish_rate is the upper bound), so the rate is '
            f'that of {source} (device reports {results.get("device_reports_hz")} Hz).'))


def generic_run(spec: DriverSpec, domain: int) -> dict:
    """The benchmark of a driver without a ``bench_<module>.py``: its registered in-process
    simulator (``spec.sim_handle``), the node at ``spec.bench.publish_rate`` with the spec's
    link parameters; the joint_command stream when the handle shows device targets
    (``SimHandle.device_target``); and, with ``spec.bench.max_rate``, the joint_states rate
    the node reaches there."""
    settings = spec.bench
    joint = settings.stream_joint or spec.joints[0]
    with tempfile.TemporaryDirectory(prefix=f'bench-{spec.name}-') as workdir:
        handle = make_handle(spec, Path(workdir))
        handle.start()
        results: dict = {'transport': f'in-process {type(handle).__name__}'}
        try:
            stream = recorder = None
            try:
                handle.device_target(joint)
            except NotImplementedError as exc:
                add_note(results, f'no joint_command stream: {exc}')
            else:
                recorder = DeviceRecorder(handle, {
                    'received': lambda: handle.device_target(joint)})
                stream = StreamSpec(joint, settings.stream_base, float, settings.stream_tolerance,
                                    move_targets=settings.move_targets,
                                    node_name=spec.node_name)
            base = {**handle.node_parameters(), 'command_timeout': 0.0,
                    'presets_file': str(Path(workdir, 'presets.yaml'))}
            results.update(node_figures(domain, spec.package,
                                        {**base, 'publish_rate': settings.publish_rate},
                                        stream, recorder, executable=spec.node_executable))
            if settings.max_rate:
                fast = node_figures(domain, spec.package,
                                    {**base, 'publish_rate': settings.max_rate},
                                    window_seconds=3.0, executable=spec.node_executable,
                                    cpu_reference=False)
                results['max_rate_test'] = {'publish_rate': settings.max_rate,
                                            'joint_states_hz': fast['joint_states_hz']}
        finally:
            handle.stop()
    check_targets(results)
    return results
