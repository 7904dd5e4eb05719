"""Shared measurement code for ``make bench``: every figure next to its reference.

A driver benchmark (``bench/bench_<driver>.py``) calls these helpers and
returns a JSON-able dict. References measured in the same run:

* the wire's physical limit (``wire_limit_frames_per_s``: bits on the wire);
* a bare rclpy JointState publisher/subscriber pair on this machine
  (:func:`rclpy_reference`), the floor for any driver's latency and CPU.

Latency definitions (wall clock, one machine):

* ``sim_to_subscriber``: from the time the device data reached the driver (the
  ``header.stamp`` the driver puts on joint_states, taken as the frame is read
  from the simulator) to the JointState arriving at a subscriber; loopback
  transfer from the simulator adds microseconds (``loopback_rtt_us``).
* ``command_stream`` (``command_stream.py``): from a ``joint_command`` publish, in a
  steady stream, to the simulator receiving the command bytes and the device acting.
"""

from __future__ import annotations

import contextlib
import gc
import math
import os
import socket
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from gimbal_driver_testing import ManagedProcess, ros_env, wait_for
from gimbal_driver_testing.ros import RosTestClient

ROOT = Path(__file__).resolve().parent.parent


def freeze_heap() -> None:
    """Collect, then freeze what is alive, before a driver's runs.

    The simulators run in this process, so a full garbage collection here stops the
    simulated device with everything else: after two drivers' runs the heap held 60,000 to
    95,000 objects, a collection took 25-50 ms, and one in Capture's tracking left the
    node's joint_states without a new sample for 40 ms (the state age and the error of the
    tracking figures). A device has no such pause; frozen objects are never traversed
    again, and only what the driver's own runs make is collected.
    """
    gc.collect()
    gc.freeze()


def percentiles(samples: list[float]) -> dict[str, float]:
    """p50/p99/max in milliseconds of samples in seconds."""
    if not samples:
        return {'n': 0}
    ordered = sorted(samples)
    p99 = ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))]
    return {
        'n': len(ordered),
        'p50_ms': round(statistics.median(ordered) * 1e3, 3),
        'p99_ms': round(p99 * 1e3, 3),
        'max_ms': round(ordered[-1] * 1e3, 3),
    }


def rate(operation: Callable[[], object], seconds: float = 1.0) -> float:
    """Calls per second of ``operation`` on this thread (one core)."""
    count = 0
    start = time.perf_counter()
    deadline = start + seconds
    while True:
        for _ in range(200):
            operation()
        count += 200
        now = time.perf_counter()
        if now >= deadline:
            return count / (now - start)


def wire_limit_frames_per_s(frame_bytes: int, bits_per_second: float, bits_per_byte: int = 10,
                            overhead_bits: int = 0) -> float:
    """Frames per second the physical link can carry (UART: 10 bits a byte with 8N1)."""
    return bits_per_second / (frame_bytes * bits_per_byte + overhead_bits)


def can_frame_bits(data_bytes: int) -> int:
    """Worst-case bits of a CAN 2.0A data frame with stuffing (for the bus-limit reference)."""
    base = 44 + 8 * data_bytes
    return base + (34 + 8 * data_bytes - 1) // 4 + 3 + 7  # stuff bits, IFS


def loopback_rtt_us(samples: int = 200) -> float:
    """Median TCP round trip on 127.0.0.1, the simulator-to-driver transfer floor."""
    server = socket.create_server(('127.0.0.1', 0))
    port = server.getsockname()[1]

    def echo() -> None:
        conn, _ = server.accept()
        with conn:
            while data := conn.recv(64):
                conn.sendall(data)

    thread = threading.Thread(target=echo, daemon=True, name='loopback-echo')
    thread.start()
    client = socket.create_connection(('127.0.0.1', port))
    client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    times = []
    for _ in range(samples):
        start = time.perf_counter()
        client.sendall(b'x')
        client.recv(1)
        times.append(time.perf_counter() - start)
    client.close()
    server.close()
    return round(statistics.median(times) * 1e6, 1)


def cpu_percent(pid: int, seconds: float) -> float:
    """CPU use of a process over ``seconds``, in % of one core."""
    return cpu_percents([pid], seconds)[0]


def process_cpu_seconds(pid: int) -> float:
    """CPU time of a whole process (all threads), in s, from the kernel's per-process CPU
    clock: nanoseconds of run time, not /proc's 10 ms ticks.

    Tick accounting charges a whole tick to whichever task runs when the tick fires, so a
    node that is busy 0.1-0.3 ms at a time 50 times a second was charged at random: the
    same bare publisher read 2.1 to 4.3 % between windows. The clock id of another process
    is ``(~pid << 3) | CPUCLOCK_SCHED`` (Linux ``clock_getcpuclockid``); /proc ticks are the
    fallback where that clock cannot be read.
    """
    try:
        return time.clock_gettime((~pid << 3) | 2)
    except OSError:
        return proc_stat_cpu_seconds(Path(f'/proc/{pid}/stat'))


def proc_stat_cpu_seconds(stat: Path) -> float:
    """utime + stime of a /proc ``stat`` file (a process or one of its tasks), in s."""
    fields = stat.read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def cpu_percents(pids: list[int], seconds: float) -> list[float]:
    """CPU use of each process over one and the same window of ``seconds``, in % of one
    core: a node and its reference measured side by side see the same machine."""
    begin, start = [process_cpu_seconds(pid) for pid in pids], time.monotonic()
    time.sleep(seconds)
    end, wall = [process_cpu_seconds(pid) for pid in pids], time.monotonic() - start
    return [round(100.0 * (after - before) / wall, 2)
            for before, after in zip(begin, end, strict=True)]


def thread_cpu_seconds(pid: int) -> dict[int, float]:
    """CPU time (s) of each thread of a process, from /proc ticks (a per-thread CPU clock
    can only be read from inside its process): for shares over a 10 s window."""
    times = {}
    for task in Path(f'/proc/{pid}/task').iterdir():
        try:
            times[int(task.name)] = proc_stat_cpu_seconds(task / 'stat')
        except OSError:
            continue   # the thread ended meanwhile
    return times


class ProbeClient:
    """A measuring rclpy node in its own context, spun by a SingleThreadedExecutor.

    Not RosTestClient: rclpy's MultiThreadedExecutor re-waits while a worker thread has not
    yet taken a ready message and spins hot on the GIL meanwhile; at 100 messages/s that
    took a whole core here, starved the callbacks and let the subscription queue fill (up to
    1 s of latency), and slowed simulators sharing the process. One thread taking each
    message at once costs a few % of a core.
    """

    def __init__(self, domain_id: int, name: str) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._publishers: dict[str, object] = {}
        self._thread = threading.Thread(target=self._spin, daemon=True, name=f'{name}-spin')
        self._thread.start()

    def _spin(self) -> None:
        # shutdown races end the spin with assorted errors; that is expected
        with contextlib.suppress(Exception):
            self.executor.spin()

    def publish(self, topic: str, msg: object) -> None:
        """Publish ``msg``; the first call creates the publisher and waits for a subscriber."""
        publisher = self._publishers.get(topic)
        if publisher is None:
            publisher = self.node.create_publisher(type(msg), topic, 10)
            self._publishers[topic] = publisher
            wait_for(lambda: publisher.get_subscription_count() > 0, 10.0,
                     f'a subscriber on {topic}')
        publisher.publish(msg)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=2.0)

    def __enter__(self) -> ProbeClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class JointStateProbe:
    """Subscribes to a joint_states topic and records arrival time and stamp of each message."""

    def __init__(self, ros: RosTestClient | ProbeClient, topic: str = 'joint_states') -> None:
        self.arrivals: list[tuple[float, float, JointState]] = []
        self._lock = threading.Lock()
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        ros.node.create_subscription(JointState, topic, self._on_message, qos)

    def _on_message(self, msg: JointState) -> None:
        now = time.time()
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        with self._lock:
            self.arrivals.append((now, stamp, msg))

    def clear(self) -> None:
        with self._lock:
            self.arrivals.clear()

    def stamp_latencies(self, since: float = 0.0, until: float = math.inf) -> list[float]:
        """Stamp-to-arrival latencies, of the messages stamped in [since, until] (wall time)."""
        with self._lock:
            return [arrival - stamp for arrival, stamp, _ in self.arrivals
                    if stamp > 0 and since <= stamp <= until]

    def achieved_rate(self, seconds: float) -> float:
        self.clear()
        time.sleep(seconds)
        with self._lock:
            if len(self.arrivals) < 2:
                return 0.0
            return round((len(self.arrivals) - 1) / (self.arrivals[-1][0] - self.arrivals[0][0]), 1)


@contextlib.contextmanager
def reference_publisher(ros: ProbeClient, domain: int, rate_hz: float):
    """A bare rclpy JointState publisher process at ``rate_hz`` with ``ros`` subscribed to
    it (as a node's joint_states have the bench's probe); yields (process, its probe)."""
    script = ROOT / 'bench' / 'reference_publisher.py'
    publisher = ManagedProcess([sys.executable, str(script), str(rate_hz)], ros_env(domain),
                               name='reference_publisher')
    try:
        probe = JointStateProbe(ros, 'reference_joint_states')
        wait_for(lambda: len(probe.arrivals) > 5, 30, 'the reference publisher')
        yield publisher, probe
    finally:
        publisher.stop()


def rclpy_reference(domain: int, rate_hz: float = 100.0, seconds: float = 5.0) -> dict:
    """A bare rclpy JointState publisher (another process) and subscriber: latency and CPU."""
    with ProbeClient(domain, 'bench_reference') as ros, \
            reference_publisher(ros, domain, rate_hz) as (publisher, probe):
        # skip the start-up transient (discovery), as the driver benchmarks do
        time.sleep(2.0)
        probe.clear()
        cpu = cpu_percent(publisher.process.pid, seconds)
        latencies = probe.stamp_latencies()[-int(rate_hz * seconds):]
        achieved = probe.achieved_rate(2.0)
    return {'rate_hz': rate_hz, 'achieved_hz': achieved, 'latency': percentiles(latencies),
            'cpu_percent': cpu}


def git_revision() -> str:
    try:
        return subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=ROOT,
                              capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return 'unknown'


__all__ = ['rclpy', 'wait_for']

