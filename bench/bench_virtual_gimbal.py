"""Benchmark of the reference virtual-gimbal driver (polled over TCP, like Capture)."""

from __future__ import annotations

import time

from harness import CommandProbe, JointStateProbe, ProbeClient, cpu_percent, percentiles
from sensor_msgs.msg import JointState

from gimbal_driver_common.testing import ManagedProcess, wait_for
from gimbal_driver_common.virtual_gimbal import make_server


def run(domain: int) -> dict:
    server, device = make_server()
    probe = CommandProbe(server)
    results: dict = {'transport': 'tcp loopback, polled'}
    try:
        for rate, seconds in ((50.0, 5.0), (200.0, 3.0)):
            node = ManagedProcess.ros('gimbal_driver_common', 'virtual_gimbal_node', domain, [
                '--ros-args', '-p', f'port:={server.port}', '-p', f'publish_rate:={rate}',
                '-p', 'command_timeout:=0.0'])
            try:
                with ProbeClient(domain, 'bench_virtual') as ros:
                    states = JointStateProbe(ros)
                    wait_for(lambda s=states: len(s.arrivals) > 10, 30, 'joint_states')
                    if rate == 50.0:
                        results['publish_rate'] = rate
                        results['cpu_percent'] = cpu_percent(node.process.pid, seconds)
                        states.clear()
                        time.sleep(2.0)
                        results['sim_to_subscriber'] = percentiles(states.stamp_latencies())
                        # the first publish creates the publisher and waits for discovery
                        ros.publish('joint_command', JointState(name=['pan'], position=[0.0]))
                        time.sleep(0.3)
                        latencies = []
                        for i in range(30):
                            target = 0.01 * (i + 1) * (-1) ** i
                            latency = probe.measure(
                                lambda t=target: ros.publish('joint_command', JointState(
                                    name=['pan'], position=[t])),
                                lambda t=target: device.axes['pan'].target == t)
                            if latency is not None:
                                latencies.append(latency)
                            time.sleep(0.05)
                        results['command_latency'] = percentiles(latencies)
                    else:
                        achieved = states.achieved_rate(seconds)
                        results['max_rate_test'] = {'publish_rate': rate,
                                                    'joint_states_hz': achieved}
            finally:
                node.stop()
    finally:
        server.stop()
    return results
