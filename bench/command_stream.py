"""joint_command measured like a user: a steady stream, and a bare rclpy reference beside it.

A closed loop (visual servoing, a joystick, topic_based_ros2_control) publishes a
joint_command every cycle. :func:`stream_figures` runs ``stream_publisher.py`` (its own
process, timer-paced, a new target every command) against the driver node and, fed by the
same publisher half a period later on its own topic, ``reference_subscriber.py`` (a bare
rclpy subscriber writing one byte per message to a loopback socket; interleaved, the two
never race each other for the cores on the same message). Every command ``i`` targets
``base + step * i``, so each one is recognised where it lands:

* ``received``: the command bytes reaching the simulator (its server's receive hook, the
  time taken as the hook runs right after the bytes were read and handled);
* ``acting``: the simulated device holding the new target (the same instant as
  ``received`` unless the protocol stages a target first: Capture acts on MOT_Update);
* ``reference``: the reference subscriber's byte arriving on its socket.

A command the device never showed counts as ``superseded`` when a newer command of the
stream reached the device within ``LOST_AFTER_S`` of its publish (newest wins), else as
``lost``. :func:`move_and_stop_figures` times a ``~/move_to`` goal to its first device
bytes and ``~/stop`` answered while that move runs.
"""

from __future__ import annotations

import bisect
import itertools
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from harness import ROOT, ProbeClient, percentiles
from rclpy.action import ActionClient
from std_srvs.srv import Trigger

from gimbal_driver_testing import ManagedProcess, ros_env, wait_for
from gimbal_msgs.action import MoveTo

#: a command with no device bytes this long after its publish has not taken effect
LOST_AFTER_S = 0.5
#: the stream rate during which BENCH_PROFILE_DIR profiles the node
PROFILE_RATE_HZ = 50.0
STREAM_RATES_HZ = (50.0, 100.0)
#: commands per stream (BENCH_STREAM_COMMANDS overrides it, for development only)
STREAM_COMMANDS = int(os.environ.get('BENCH_STREAM_COMMANDS', '500'))
#: targets: the reference ratios the issue sets (p99 within 3x, p50 within 1.5x)
P99_RATIO_TARGET = 3.0
P50_RATIO_TARGET = 1.5
#: ~/stop under a joint_command stream: calls (>= 500 for a p99; BENCH_STOP_CALLS overrides
#: it, for development only), their rate, and the stream's rate
STOP_CALLS = int(os.environ.get('BENCH_STOP_CALLS', '500'))
STOP_CALL_HZ = 10.0
STOP_STREAM_HZ = 50.0
#: how far (rad) the stream under ~/stop walks in all: small steps stay inside the limits
STOP_STREAM_SPAN = 0.4


@dataclass
class StreamSpec:
    """How a driver's device shows one joint's commanded target.

    ``to_device`` maps a joint target (rad) to the value the :class:`DeviceRecorder` points
    read from the simulator; ``tolerance`` (device units) must stay below half a step.
    """

    joint: str
    base: float
    to_device: Callable[[float], float]
    tolerance: float
    step: float = 0.001
    move_targets: tuple[float, float] = (-0.4, 0.4)
    node_name: str = ''

    def index_of(self, value: float, count: int) -> int | None:
        """The command index whose target the device value shows, if any."""
        first, second = self.to_device(self.base), self.to_device(self.base + self.step)
        index = round((value - first) / (second - first))
        if 0 <= index < count and abs(self.to_device(self.base + self.step * index)
                                      - value) <= self.tolerance:
            return index
        return None


class DeviceRecorder:
    """Receive hook on a simulator server: records each new value of every device point."""

    def __init__(self, server: object, points: dict[str, Callable[[], float | None]]) -> None:
        self._points = points
        self._lock = threading.Lock()
        self._last: dict[str, float | None] = dict.fromkeys(points)
        self.events: dict[str, list[tuple[float, float]]] = {name: [] for name in points}
        server.add_receive_hook(self._on_receive)

    def _on_receive(self) -> None:
        now = time.time()
        with self._lock:
            for name, read in self._points.items():
                value = read()
                if value is not None and value != self._last[name]:
                    self._last[name] = value
                    self.events[name].append((now, value))

    def take(self) -> dict[str, list[tuple[float, float]]]:
        """The events so far, and a fresh start."""
        with self._lock:
            taken = {name: list(events) for name, events in self.events.items()}
            for events in self.events.values():
                events.clear()
        return taken


class ReferenceSink:
    """Loopback TCP listener timestamping each byte of the reference subscriber on arrival."""

    def __init__(self) -> None:
        self._server = socket.create_server(('127.0.0.1', 0))
        self.port = self._server.getsockname()[1]
        self._lock = threading.Lock()
        self.arrivals: list[tuple[float, int]] = []
        threading.Thread(target=self._serve, daemon=True, name='reference-sink').start()

    def _serve(self) -> None:
        try:
            conn, _ = self._server.accept()
        except OSError:
            return
        with conn:
            while data := conn.recv(4096):
                now = time.time()
                with self._lock:
                    self.arrivals.extend((now, byte) for byte in data)

    def take(self) -> list[tuple[float, int]]:
        with self._lock:
            taken, self.arrivals = self.arrivals, []
        return taken

    def close(self) -> None:
        self._server.close()


def reference_indices(arrivals: list[tuple[float, int]], count: int) -> dict[int, float]:
    """Command index -> arrival time, matching each byte (index mod 256) in stream order."""
    first: dict[int, float] = {}
    index = -1
    for arrived, byte in arrivals:
        candidate = index + 1 + ((byte - index - 1) % 256)
        if candidate >= count:
            break
        index = candidate
        first[index] = arrived
    return first


def device_indices(events: list[tuple[float, float]], spec: StreamSpec,
                   count: int) -> dict[int, float]:
    """Command index -> time the device first showed its target."""
    first: dict[int, float] = {}
    for arrived, value in events:
        index = spec.index_of(value, count)
        if index is not None and index not in first:
            first[index] = arrived
    return first


def delivery_figures(publish_times: list[float], first: dict[int, float]) -> dict:
    """Latency percentiles and how many commands never took effect (superseded or lost)."""
    count = len(publish_times)
    latencies = [first[i] - publish_times[i] for i in sorted(first) if i < count]
    # earliest device time of any command newer than i (suffix minimum)
    newer_seen = [float('inf')] * (count + 1)
    for i in range(count - 1, -1, -1):
        newer_seen[i] = min(newer_seen[i + 1], first.get(i, float('inf')))
    missing = [i for i in range(count) if i not in first]
    superseded = sum(1 for i in missing
                     if newer_seen[i + 1] <= publish_times[i] + LOST_AFTER_S)
    figures = percentiles(latencies)
    figures.update({
        'commands': count,
        'took_effect': len(latencies),
        'superseded': superseded,
        'lost': len(missing) - superseded,
        f'later_than_{LOST_AFTER_S:g}_s': sum(1 for x in latencies if x > LOST_AFTER_S),
    })
    return figures


def compare(driver: dict, reference: dict) -> dict:
    """Ratios to the reference of the same stream and the issue's three targets."""
    if not driver.get('n') or not reference.get('n'):
        return {}
    p99_ratio = driver['p99_ms'] / reference['p99_ms']
    p50_ratio = driver['p50_ms'] / reference['p50_ms']
    return {
        'p99_ratio': round(p99_ratio, 2),
        'p50_ratio': round(p50_ratio, 2),
        'targets': {
            f'p99 <= {P99_RATIO_TARGET:g}x reference p99': p99_ratio <= P99_RATIO_TARGET,
            f'p50 <= {P50_RATIO_TARGET:g}x reference p50': p50_ratio <= P50_RATIO_TARGET,
            'no command lost (superseded ones aside)': driver['lost'] == 0,
        },
    }


def run_stream(domain: int, spec: StreamSpec, recorder: DeviceRecorder, rate_hz: float,
               count: int, profile: Callable[[float], dict] | None = None) -> dict:
    """One stream of ``count`` commands at ``rate_hz`` to the node and the reference;
    ``profile(seconds)`` runs while the stream does."""
    sink = ReferenceSink()
    env = ros_env(domain)
    reference = ManagedProcess([sys.executable, str(ROOT / 'bench' / 'reference_subscriber.py'),
                                str(sink.port)], env, name='reference_subscriber')
    with tempfile.TemporaryDirectory(prefix='bench-stream-') as tmp:
        output = Path(tmp, 'publish_times.json')
        publisher = ManagedProcess([
            sys.executable, str(ROOT / 'bench' / 'stream_publisher.py'), repr(rate_hz),
            str(count), spec.joint, repr(spec.base), repr(spec.step), '1', str(output)],
            env, name='stream_publisher')
        try:
            extra = profile(count / rate_hz) if profile is not None else {}
            wait_for(lambda: output.exists() or not publisher.running,
                     60.0 + 2 * count / rate_hz, 'the command stream')
            if not output.exists():
                raise RuntimeError(f'stream publisher failed:\n{publisher.output()[-2000:]}')
            time.sleep(LOST_AFTER_S + 0.5)   # the last commands still count
            published = json.loads(output.read_text())
            publish_times = published['publish_times']
            reference_times = published['reference_publish_times']
        finally:
            publisher.stop(timeout=5.0)
            reference.stop(timeout=5.0)
            sink.close()
    events = recorder.take()
    intervals = [b - a for a, b in itertools.pairwise(publish_times)]
    ref = delivery_figures(reference_times, reference_indices(sink.take(), count))
    figures: dict = {
        'rate_hz': rate_hz,
        'publish_interval': percentiles(intervals),
        'reference_byte_on_socket': ref,
        **extra,
    }
    for point in ('received', 'acting'):
        if point in events:
            driver = delivery_figures(publish_times, device_indices(events[point], spec,
                                                                    count))
            driver.update(compare(driver, ref))
            figures[f'device_{point}'] = driver
    return figures


def stream_figures(domain: int, spec: StreamSpec, recorder: DeviceRecorder,
                   count: int = STREAM_COMMANDS,
                   rates: tuple[float, ...] = STREAM_RATES_HZ,
                   node_pid: int | None = None) -> dict:
    """The stream at each rate. With ``BENCH_PROFILE_DIR`` set, py-spy samples the node
    during the 50 Hz stream (see :func:`profile_node`)."""
    recorder.take()
    results = {}
    profile_dir = os.environ.get('BENCH_PROFILE_DIR')
    for rate_hz in rates:
        profile = None
        if profile_dir and node_pid is not None and rate_hz == PROFILE_RATE_HZ:
            def profile(seconds: float, pid: int = node_pid) -> dict:
                return profile_node(pid, seconds, Path(profile_dir), spec.node_name)
        results[f'{rate_hz:g}_hz'] = run_stream(domain, spec, recorder, rate_hz, count,
                                                profile)
    return results


def profile_node(pid: int, seconds: float, directory: Path, name: str) -> dict:
    """py-spy samples of every thread of the node (collapsed stacks, one file per mode):
    ``cpu`` (threads on a CPU) and ``gil`` (the thread holding the GIL)."""
    directory.mkdir(parents=True, exist_ok=True)
    files = {}
    half = max(1, int(seconds / 2))
    for mode, flags in (('cpu', []), ('gil', ['--gil'])):
        path = directory / f'{name}_{PROFILE_RATE_HZ:g}hz_{mode}.txt'
        done = subprocess.run(
            [str(Path(sys.executable).parent / 'py-spy'), 'record', '--pid', str(pid),
             '--duration', str(half), '--rate', '250', '--format', 'raw', '--threads',
             '--nonblocking', '--output', str(path), *flags],
            capture_output=True, text=True, check=False)
        files[mode] = str(path) if done.returncode == 0 else done.stderr.strip()[-300:]
    return {'profile': files}


def in_executor(ros: ProbeClient, call: Callable[[], object], timeout: float) -> object:
    """Run ``call`` in the client's executor thread and return what it returned.

    rclpy's ActionClient registers a request only after sending it; called from another
    thread, the response can be taken first and is dropped ("Ignoring unexpected goal
    response"), and the goal is never accepted. In the executor thread that cannot happen.
    """
    task = ros.executor.create_task(call)
    wait_for(task.done, timeout, 'the client executor')
    return task.result()


def move_and_stop_figures(ros: ProbeClient, spec: StreamSpec, recorder: DeviceRecorder,
                          trials: int = 10, timeout: float = 10.0) -> dict:
    """~/move_to goal -> its first device bytes; ~/stop round trip while the move runs."""
    node = spec.node_name
    action = ActionClient(ros.node, MoveTo, f'/{node}/move_to')
    stop = ros.node.create_client(Trigger, f'/{node}/stop')
    if not action.wait_for_server(timeout_sec=timeout) or not stop.wait_for_service(
            timeout_sec=timeout):
        return {'error': f'/{node}/move_to or /{node}/stop not available'}
    goal_to_bytes: list[float] = []
    stop_round_trip: list[float] = []
    running_at_stop = 0
    failures: list[str] = []
    recorder.take()
    for trial in range(trials):
        target = spec.move_targets[trial % 2]
        device_target = spec.to_device(target)
        start = time.time()
        goal = MoveTo.Goal(joint_names=[spec.joint], positions=[target])
        send = in_executor(ros, lambda g=goal: action.send_goal_async(g), timeout)

        def reached(since: float = start, value: float = device_target) -> float | None:
            events = recorder.events['received']
            return next((t for t, v in list(events)
                         if t >= since and abs(v - value) <= spec.tolerance), None)

        try:
            wait_for(lambda: reached() is not None, timeout, 'the move_to bytes')
            wait_for(send.done, timeout, 'the goal acceptance')
        except TimeoutError as exc:
            failures.append(str(exc))
            continue
        goal_to_bytes.append(reached() - start)
        handle = send.result()
        result = in_executor(ros, handle.get_result_async, timeout)
        still_running = not result.done()
        answered: list[float] = []
        call_start = time.time()
        answer = stop.call_async(Trigger.Request())
        # timed by the future's callback (the executor thread), not by wait_for's 20 ms polls
        answer.add_done_callback(lambda _future, times=answered: times.append(time.time()))
        wait_for(lambda times=answered: times, timeout, 'the ~/stop reply')
        stop_round_trip.append(answered[0] - call_start)
        if not answer.result().success:
            failures.append(f'~/stop: {answer.result().message}')
        running_at_stop += still_running
        try:
            wait_for(result.done, timeout, 'the move_to result after ~/stop')
        except TimeoutError as exc:   # a finding, not a reason to lose the other figures
            failures.append(f'trial {trial}: {exc}')
            handle.cancel_goal_async()
        recorder.take()
    figures = {
        'move_to_goal_to_first_device_bytes': percentiles(goal_to_bytes),
        'stop_round_trip_during_move': percentiles(stop_round_trip),
        'move_running_when_stop_sent': f'{running_at_stop} of {len(stop_round_trip)}',
    }
    if failures:
        figures['failures'] = failures[:5]
    return figures


def stop_during_stream_figures(ros: ProbeClient, domain: int, spec: StreamSpec,
                               recorder: DeviceRecorder, calls: int = STOP_CALLS,
                               timeout: float = 10.0) -> dict:
    """``~/stop`` while a 50 Hz joint_command stream runs (a closed loop that a user stops).

    The node's executor must stay free for the service while joint_command callbacks
    arrive every 20 ms (ARCHITECTURE.md's thread rule: the callback never waits for a device
    reply). ``calls`` stops, one every 1/STOP_CALL_HZ s; each timed as its service round
    trip (the future's done callback) and, where the recorder has a ``stopped`` point (a
    counter the simulator bumps when an axis acts on a stop), from the call to the device
    acting on it.
    """
    stop = ros.node.create_client(Trigger, f'/{spec.node_name}/stop')
    if not stop.wait_for_service(timeout_sec=timeout):
        return {'error': f'/{spec.node_name}/stop not available'}
    count = int((calls / STOP_CALL_HZ + 5.0) * STOP_STREAM_HZ)
    sink = ReferenceSink()   # the publisher waits for the reference subscriber too
    env = ros_env(domain)
    reference = ManagedProcess([sys.executable, str(ROOT / 'bench' / 'reference_subscriber.py'),
                                str(sink.port)], env, name='reference_subscriber')
    round_trips: list[float] = []
    to_device: list[float] = []
    failures: list[str] = []
    recorder.take()
    with tempfile.TemporaryDirectory(prefix='bench-stop-') as tmp:
        output = Path(tmp, 'publish_times.json')
        publisher = ManagedProcess([
            sys.executable, str(ROOT / 'bench' / 'stream_publisher.py'), repr(STOP_STREAM_HZ),
            str(count), spec.joint, repr(spec.base), repr(STOP_STREAM_SPAN / count), '1',
            str(output)], env, name='stream_publisher')
        try:
            wait_for(lambda: recorder.events['received'], 60.0, 'the stream at the device')
            next_call = time.monotonic()
            for _ in range(calls):
                next_call += 1.0 / STOP_CALL_HZ
                answered: list[float] = []
                call_start = time.time()
                answer = stop.call_async(Trigger.Request())
                answer.add_done_callback(lambda _f, times=answered: times.append(time.time()))
                try:
                    wait_for(lambda times=answered: times, timeout, 'the ~/stop reply')
                except TimeoutError as exc:
                    failures.append(str(exc))
                    continue
                round_trips.append(answered[0] - call_start)
                if not answer.result().success:
                    failures.append(answer.result().message)
                acted = next((t for t, _ in list(recorder.events.get('stopped', ()))
                              if t >= call_start), None)
                if acted is not None:
                    to_device.append(acted - call_start)
                time.sleep(max(0.0, next_call - time.monotonic()))
            stream_running = publisher.running
        finally:
            publisher.stop(timeout=5.0)
            reference.stop(timeout=5.0)
            sink.close()
    recorder.take()
    figures = {
        'stream_hz': STOP_STREAM_HZ, 'stop_calls': calls, 'stop_call_hz': STOP_CALL_HZ,
        'stream_still_running_after_the_last_stop': stream_running,
        'stop_round_trip': percentiles(round_trips),
    }
    if 'stopped' in recorder.events:
        figures['stop_call_to_device_acting'] = percentiles(to_device)
    if failures:
        figures['failures'] = [*failures[:5], f'{len(failures)} in all']
    return figures


def trace_figures(directory: Path, pid: int) -> dict:
    """The node's own view of the stream commands (bench/node_hook, ``BENCH_TRACE_DIR``):
    rclpy delivery (publish -> callback entry), the driver's work before its first device
    write, the writes of one command (first to last) and the whole callback."""
    path = directory / f'trace_{pid}.json'
    if not path.exists():
        return {'error': f'no trace {path} (the node did not exit cleanly?)'}
    data = json.loads(path.read_text())
    records = [r for r in data['records'] if r['index'].isdigit()]
    written = [r for r in records if r['writes']]
    threads: dict[str, int] = {}
    for record in records:
        name = record['thread'].rsplit('_', 1)[0]
        threads[name] = threads.get(name, 0) + 1
    return {
        'executor': data['executor'],
        'commands_handled': len(records),
        'callback_threads': threads,
        'publish_to_callback': percentiles([r['entry'] - r['published'] for r in records]),
        # the executor thread's last rcl_wait return before the callback: publish -> wait
        # return is DDS and the wake-up (GIL included), wait return -> callback is rclpy's
        # Python (ready-entity scan, take, deserialise)
        'publish_to_wait_return': percentiles([r['waited'] - r['published'] for r in records
                                               if r.get('waited', 0) > r['published']]),
        'wait_return_to_callback': percentiles([r['entry'] - r['waited'] for r in records
                                                if r.get('waited', 0) > r['published']]),
        'callback_to_first_write': percentiles([r['writes'][0] - r['entry']
                                                for r in written]),
        'first_to_last_write': percentiles([r['writes'][-1] - r['writes'][0]
                                            for r in written]),
        'writes_per_command_median': statistics.median(len(r['writes']) for r in written)
        if written else 0,
        'callback_duration': percentiles([r['returned'] - r['entry'] for r in records]),
        'publish_to_callback_by_phase': delivery_by_phase(records, data.get('joint_states', [])),
    }


def delivery_by_phase(records: list[dict], joint_states: list[list[float]]) -> dict:
    """publish -> callback grouped by the command's phase in the node's cycle: the time
    since the node last started publishing joint_states. A command stream at the node's own
    rate keeps one phase for the whole run, so a slow phase shows as a slow p50."""
    starts = sorted(entry[0] for entry in joint_states)
    if not starts:
        return {}
    buckets: dict[str, list[float]] = {}
    edges = (0.001, 0.002, 0.005, 0.010, 0.020)
    for record in records:
        k = bisect.bisect_right(starts, record['published']) - 1
        if k < 0:
            continue
        phase = record['published'] - starts[k]
        label = next((f'< {edge * 1e3:g} ms' for edge in edges if phase < edge), '>= 20 ms')
        buckets.setdefault(label, []).append(record['entry'] - record['published'])
    order = [f'< {edge * 1e3:g} ms' for edge in edges] + ['>= 20 ms']
    return {label: percentiles(buckets[label]) for label in order if label in buckets}
