"""Test domains never collide with a live system: the pool comes from GIMBAL_TEST_DOMAINS
(default DEFAULT_DOMAINS, within what Fast DDS accepts), and the ROS test client refuses to
command a domain where a node of a process outside the test run is seen, and a closed
client leaves the domain."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pytest
import rclpy
from rclpy.action import ActionServer
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

import gimbal_driver_testing
from gimbal_driver_testing import (
    DEFAULT_DOMAINS,
    DOMAINS_VARIABLE,
    MAX_DOMAIN,
    DomainLease,
    ManagedProcess,
    domain_pool,
    ros_env,
    wait_for,
)
from gimbal_driver_testing.graph_guard import (
    ForeignNodesError,
    foreign_nodes,
    live_processes,
    own_pids,
    participant_pid_bits,
    run_root,
)
from gimbal_driver_testing.ros import RosTestClient
from gimbal_msgs.action import MoveTo


def test_the_default_pool_keeps_off_live_and_shell_domains() -> None:
    pool = domain_pool({})
    assert pool == domain_pool({DOMAINS_VARIABLE: DEFAULT_DOMAINS})
    assert pool == (*range(20, 102), *range(215, 233))
    assert max(pool) <= MAX_DOMAIN == 232
    assert not set(pool) & set(range(20)), '0-19: the domains a live system most likely uses'
    assert not set(pool) & set(range(110, 200)), 'scripts/ros_env.sh gives shells 110-199'


@pytest.mark.parametrize(('text', 'pool'), [
    ('150-229', tuple(range(150, 230))),
    ('30', (30,)),
    (' 30, 31 ,40-42', (30, 31, 40, 41, 42)),
    ('40-42,41', (40, 41, 42)),
    ('232', (232,)),
])
def test_the_variable_names_ranges_and_ids(text: str, pool: tuple[int, ...]) -> None:
    assert domain_pool({DOMAINS_VARIABLE: text}) == pool


@pytest.mark.parametrize(('text', 'says'), [
    ('0-50', "'0-50' is outside 1-232"),
    ('0', "'0' is outside 1-232"),
    ('200-233', "'200-233' is outside 1-232"),
    ('50-40', "the range '50-40' is empty"),
    ('abc', "'abc' is not a domain id or a range"),
    ('20,,30', "'' is not a domain id or a range"),
    ('20-', "'20-' is not a domain id or a range"),
])
def test_a_bad_pool_is_refused_naming_the_variable(text: str, says: str) -> None:
    with pytest.raises(ValueError, match='GIMBAL_TEST_DOMAINS') as raised:
        domain_pool({DOMAINS_VARIABLE: text})
    assert says in str(raised.value)


def test_a_lease_comes_from_the_configured_pool(monkeypatch, tmp_path: Path) -> None:
    """Two ids configured: two leases get them both, a third finds none and says which
    pool it searched. (The lock files in a private directory: other runs on this machine
    hold theirs.)"""
    monkeypatch.setattr(gimbal_driver_testing, '_LOCK_DIR', tmp_path)
    monkeypatch.setenv(DOMAINS_VARIABLE, '61,67')
    with DomainLease() as first, DomainLease() as second:
        assert {first, second} == {61, 67}
        with pytest.raises(RuntimeError, match="GIMBAL_TEST_DOMAINS='61,67'"):
            DomainLease().acquire()
    with DomainLease() as again:
        assert again in (61, 67)


def test_a_bad_variable_stops_the_lease(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setattr(gimbal_driver_testing, '_LOCK_DIR', tmp_path)
    monkeypatch.setenv(DOMAINS_VARIABLE, '0-10')
    with pytest.raises(ValueError, match='0 is the default domain'):
        DomainLease().acquire()


# ---------------------------------------------------------------- whose node is it

def fast_dds_gid(pid: int) -> list[int]:
    """A Fast DDS endpoint GID as rclpy gives it: vendor 01.0f, host id, pid's low 16 bits."""
    return [0x01, 0x0F, 0x78, 0xFD, *(pid & 0xFFFF).to_bytes(2, 'little'), 0x15, 0xC4,
            *([0] * 8)]


def test_the_pid_bits_of_a_fast_dds_gid() -> None:
    assert participant_pid_bits(fast_dds_gid(24905)) == 24905
    assert participant_pid_bits(fast_dds_gid(70000)) == 70000 & 0xFFFF
    assert participant_pid_bits([0x01, 0x10, *([0] * 14)]) is None   # another vendor


def test_a_node_is_foreign_when_its_live_process_is_not_the_tests() -> None:
    parents = {1: 0, 100: 1, 200: 100, 201: 200, 300: 1}   # 100: the test, 300: a robot
    own = own_pids(parents, me=100, started={250})
    assert own == {100, 200, 201, 250}
    endpoints = [('/test_client', fast_dds_gid(100)), ('/capture_driver', fast_dds_gid(201)),
                 ('/robot/gimbal', fast_dds_gid(300)), ('/stopped', fast_dds_gid(400)),
                 ('/cyclone', [0x01, 0x10, *([0] * 14)])]
    assert foreign_nodes(endpoints, parents, own) == [
        '/cyclone (not a Fast DDS participant: its process cannot be told)',
        '/robot/gimbal (pid 300)']
    assert foreign_nodes(endpoints[:2] + endpoints[3:4], parents, own) == []


def test_the_workers_of_one_run_are_its_own_and_nothing_else_is() -> None:
    """Under pytest-xdist the run's root is the controller: a sibling worker's client, with
    the same node name as this one's, is the run's; a robot's node beside the run and a
    process re-parented away from it are not. Identity is the GUID's pid, not the name."""
    parents = {1: 0, 50: 1, 90: 50, 100: 90, 101: 90, 201: 101, 300: 50, 400: 1}
    # 50: the shell, 90: the controller, 100/101: workers, 201: a node worker 101 started,
    # 300: a robot launched from the same shell, 400: a daemon forked off by a test
    own = own_pids(parents, me=90, started=set())
    assert own == {90, 100, 101, 201}
    endpoints = [('/gimbal_test_client', fast_dds_gid(100)),
                 ('/gimbal_test_client', fast_dds_gid(101)),
                 ('/kessler_kos_driver', fast_dds_gid(201)),
                 ('/gimbal_test_client', fast_dds_gid(300)),
                 ('/daemon', fast_dds_gid(400))]
    assert foreign_nodes(endpoints, parents, own) == ['/daemon (pid 400)',
                                                      '/gimbal_test_client (pid 300)']


def test_the_run_root_is_the_xdist_controller_in_a_worker() -> None:
    assert run_root({'PYTEST_XDIST_WORKER': 'gw3'}) == os.getppid()
    assert run_root({}) == os.getpid()
    assert os.getpid() in own_pids(live_processes(), run_root(), set())


def test_live_processes_reads_this_process_and_its_parent() -> None:
    parents = live_processes()
    assert parents[os.getpid()] == os.getppid()


LISTENER = textwrap.dedent('''
    import os, sys, time
    if os.fork():
        os._exit(0)            # the child lives on, no longer a descendant of the test
    import rclpy
    from std_msgs.msg import String
    rclpy.init()
    node = rclpy.create_node('live_robot_node')
    node.create_subscription(String, '/joint_command_probe', lambda msg: None, 10)
    print('listening', os.getpid(), flush=True)
    deadline = time.monotonic() + 120
    while rclpy.ok() and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.2)
''')


@pytest.mark.ros
def test_the_client_refuses_to_publish_beside_a_node_it_did_not_start(tmp_path: Path) -> None:
    """A node of a process outside the test run (forked off and re-parented) on the leased
    domain: the first publish raises, naming the node and the variable, and nothing is
    published; a node the test started is commanded as before."""
    output = tmp_path / 'listener.out'
    with DomainLease() as domain, output.open('w') as stream:
        subprocess.run([sys.executable, '-c', LISTENER], env=ros_env(domain), check=True,
                       stdout=stream, stderr=subprocess.STDOUT, timeout=30)
        line = wait_for(lambda: 'listening' in output.read_text() and output.read_text(), 30,
                        'the outside listener')
        outside = int(line.split()[1])
        try:
            assert outside not in own_pids(live_processes(), run_root(),
                                           gimbal_driver_testing.STARTED_PIDS)
            with RosTestClient(domain) as ros:
                with pytest.raises(ForeignNodesError) as raised:
                    ros.publish('/joint_command_probe', String(data='move'))
                assert '/live_robot_node' in str(raised.value)
                assert DOMAINS_VARIABLE in str(raised.value)
                assert f'domain {domain}' in str(raised.value)
        finally:
            os.kill(outside, signal.SIGKILL)


@pytest.mark.ros
def test_the_client_commands_a_node_the_test_started() -> None:
    code = textwrap.dedent('''
        import rclpy
        from std_msgs.msg import String
        rclpy.init()
        node = rclpy.create_node('started_by_the_test')
        node.create_subscription(String, '/joint_command_probe',
                                 lambda msg: print('got', msg.data, flush=True), 10)
        print('listening', flush=True)
        rclpy.spin(node)
    ''')
    with DomainLease() as domain, ManagedProcess([sys.executable, '-c', code],
                                                 ros_env(domain)) as listener:
        listener.wait_for_output('listening', 30)
        with RosTestClient(domain) as ros:
            ros.publish('/joint_command_probe', String(data='move'))
            listener.wait_for_output('got move', 30)


@pytest.mark.ros
def test_a_closed_client_leaves_the_domain_also_after_an_action() -> None:
    """An action client holds the rcl node, so a client that had sent a goal stayed a DDS
    participant after close() (until a garbage collection), on a domain whose lease it had
    released: the next test there, in another worker, saw it. Once closed it is gone."""
    with DomainLease() as domain:
        context = Context()
        rclpy.init(context=context, domain_id=domain)
        try:
            server = rclpy.create_node('probe_action_server', context=context)
            action = ActionServer(
                server, MoveTo, '/probe_move',
                lambda handle: (handle.succeed(), MoveTo.Result(success=True))[1])
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(server)
            spin = threading.Thread(target=executor.spin, daemon=True)
            spin.start()
            client = RosTestClient(domain, 'closing_client')
            try:
                _, status, _ = client.run_action(MoveTo, '/probe_move', MoveTo.Goal())
                assert status == 4   # succeeded
                wait_for(lambda: 'closing_client' in server.get_node_names(), 30,
                         'the server to see the client')
            finally:
                client.close()
            wait_for(lambda: 'closing_client' not in server.get_node_names(), 30,
                     'the closed client to leave the domain')
            executor.shutdown(timeout_sec=5.0)
            spin.join(timeout=5.0)
            action.destroy()  # it holds the rcl node: the server would stay on the domain
            server.destroy_node()
        finally:
            rclpy.shutdown(context=context)
