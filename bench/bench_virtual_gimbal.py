"""Benchmark of the reference virtual-gimbal driver (polled over TCP, like Capture)."""

from __future__ import annotations

from command_stream import DeviceRecorder, StreamSpec
from driver_bench import node_figures
from harness import JointStateProbe, ProbeClient

from gimbal_driver_common.testing import ManagedProcess, wait_for
from gimbal_driver_common.virtual_gimbal import make_server

PACKAGE = 'gimbal_driver_common'
EXECUTABLE = 'virtual_gimbal_node'
MAX_RATE_HZ = 200.0


def run(domain: int) -> dict:
    server, device = make_server()
    pan = device.axes['pan']
    # a MOVE line sets the target as it is handled; the model steps only on the next request
    recorder = DeviceRecorder(server, {'received': lambda: pan.target})
    stream = StreamSpec('pan', -0.25, float, 1e-6, node_name='virtual_gimbal')
    results: dict = {'transport': 'tcp loopback, polled'}
    try:
        results.update(node_figures(domain, PACKAGE, {
            'port': server.port, 'publish_rate': 50.0, 'command_timeout': 0.0,
        }, stream, recorder, executable=EXECUTABLE))
        node = ManagedProcess.ros(PACKAGE, EXECUTABLE, domain, [
            '--ros-args', '-p', f'port:={server.port}', '-p', f'publish_rate:={MAX_RATE_HZ}',
            '-p', 'command_timeout:=0.0'])
        try:
            with ProbeClient(domain, 'bench_virtual') as ros:
                states = JointStateProbe(ros)
                wait_for(lambda: len(states.arrivals) > 10, 30, 'joint_states')
                results['max_rate_test'] = {'publish_rate': MAX_RATE_HZ,
                                            'joint_states_hz': states.achieved_rate(3.0)}
        finally:
            node.stop()
    finally:
        server.stop()
    return results
