"""What a process that stood still costs the messages sent to it meanwhile (Fast DDS).

`python bench/stalled_reader.py [--stop 5] [--trials 5] [--heartbeat-ms MS]` (not part of
`make bench`): a Trigger server runs as a process of its own, subscribed to a topic that
this process floods at about 200 Hz. Each trial stops the server (SIGSTOP) for `--stop`
seconds while a request to it is on its way and the flood goes on, resumes it (SIGCONT)
and times the answer from the resume. Then the same with a new client made while the
server stands still (its matching is the discovery traffic the server missed).

A stalled reader's receive buffers fill; what overflows them is dropped, and a reliable
writer sends a dropped sample again only after its next heartbeat: Fast DDS's
`heartbeatPeriod` is 3 s by default (`WriterTimes`). `--heartbeat-ms` runs both processes
with an XML profile (`FASTRTPS_DEFAULT_PROFILES_FILE`) that shortens it, to tell that cause
from a slow resume. docs/testing.md ("A message held up for seconds") has the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_testing import DomainLease, ros_env

FLOOD_PERIOD_S = 0.005
PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <data_writer profile_name="default_writer" is_default_profile="true">
    <times><heartbeatPeriod><sec>0</sec><nanosec>{nanosec}</nanosec></heartbeatPeriod></times>
  </data_writer>
</profiles>
"""


def serve() -> int:
    """The server process: answers ``ping``, takes ``flood`` and drops it."""
    rclpy.init()
    node = rclpy.create_node('stalled_server')

    def answer(request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success = True
        return response

    node.create_service(Trigger, 'ping', answer)
    node.create_subscription(JointState, 'flood', lambda message: None, 10)
    print('ready', flush=True)
    with contextlib.suppress(Exception):  # SIGTERM ends the spin however rclpy reports it
        rclpy.spin(node)
    return 0


def answered_after(future: Future, since: float, timeout: float = 10.0) -> float | None:
    """Seconds from ``since`` to the answer (None: none within ``timeout``)."""
    while not future.done():
        if time.monotonic() - since > timeout:
            return None
        time.sleep(0.001)
    return round(time.monotonic() - since, 3)


def measure(stop_s: float, trials: int, env: dict[str, str], domain: int) -> dict[str, list]:
    server = subprocess.Popen([sys.executable, __file__, '--serve'], env=env,
                              stdout=subprocess.PIPE, text=True)
    assert server.stdout is not None
    try:
        if not server.stdout.readline().startswith('ready'):
            raise RuntimeError('the server did not start')
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        node = rclpy.create_node('stalled_client', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        threading.Thread(target=executor.spin, daemon=True).start()
        client = node.create_client(Trigger, 'ping')
        if not client.wait_for_service(timeout_sec=30.0):
            raise RuntimeError('the server\'s service did not match')
        publisher = node.create_publisher(JointState, 'flood', 10)
        flooding = threading.Event()

        def flood() -> None:
            message = JointState(name=['a'] * 5, position=[0.0] * 5)
            while True:
                if flooding.is_set():
                    publisher.publish(message)
                time.sleep(FLOOD_PERIOD_S)

        threading.Thread(target=flood, daemon=True).start()
        answered_after(client.call_async(Trigger.Request()), time.monotonic())
        request, new_client = [], []
        for _ in range(trials):
            flooding.set()
            os.kill(server.pid, signal.SIGSTOP)
            future = client.call_async(Trigger.Request())
            time.sleep(stop_s)
            os.kill(server.pid, signal.SIGCONT)
            flooding.clear()
            request.append(answered_after(future, time.monotonic()))
            time.sleep(0.5)
        for _ in range(trials):
            flooding.set()
            os.kill(server.pid, signal.SIGSTOP)
            late = node.create_client(Trigger, 'ping')
            time.sleep(stop_s)
            os.kill(server.pid, signal.SIGCONT)
            flooding.clear()
            resumed = time.monotonic()
            late.wait_for_service(timeout_sec=10.0)
            new_client.append(answered_after(late.call_async(Trigger.Request()), resumed))
            node.destroy_client(late)
            time.sleep(0.5)
        executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown(context=context)
        return {'request_answered_after_resume_s': request,
                'new_client_answered_after_resume_s': new_client}
    finally:
        server.terminate()
        server.wait(timeout=10.0)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--serve', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--stop', type=float, default=5.0, help='seconds the server stands still')
    parser.add_argument('--trials', type=int, default=5)
    parser.add_argument('--heartbeat-ms', type=float, default=None,
                        help='run with this heartbeatPeriod (default: Fast DDS\'s, 3 s)')
    args = parser.parse_args()
    if args.serve:
        return serve()
    with DomainLease() as domain, tempfile.TemporaryDirectory() as scratch:
        env = ros_env(domain)
        if args.heartbeat_ms is not None:
            profile = Path(scratch) / 'heartbeat.xml'
            profile.write_text(PROFILE.format(nanosec=int(args.heartbeat_ms * 1e6)))
            env['FASTRTPS_DEFAULT_PROFILES_FILE'] = os.environ[
                'FASTRTPS_DEFAULT_PROFILES_FILE'] = str(profile)
        figures = measure(args.stop, args.trials, env, domain)
    print(json.dumps({'stop_s': args.stop, 'heartbeat_ms': args.heartbeat_ms, **figures}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
