"""RosTestClient.run_action and call against real servers in another context: a goal whose
acceptance, or an idempotent call whose reply, does not come within RESEND_S is sent
again, and the newest is waited for; anything else is sent once, and the first such call on
a client waits for discovery to settle."""

from __future__ import annotations

import threading
import time

import pytest

rclpy = pytest.importorskip('rclpy')
from rcl_interfaces.srv import ListParameters  # noqa: E402
from rclpy.action import ActionServer, GoalResponse  # noqa: E402
from rclpy.callback_groups import ReentrantCallbackGroup  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from gimbal_driver_testing import DomainLease, wait_for  # noqa: E402
from gimbal_driver_testing import ros as ros_testing  # noqa: E402
from gimbal_msgs.action import MoveTo  # noqa: E402


class SlowFirstAcceptServer:
    """A MoveTo server and a Trigger service ``read`` that answer their first request only
    after ``hold`` seconds (what a lost answer looks like to the client); each result
    names its order of arrival."""

    def __init__(self, domain_id: int, hold: float) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('slow_accept_server', context=self.context)
        self.goals = 0
        self.executed = 0  # goals whose execute callback has run
        self.reads = 0
        self.hold = hold
        self.first_answered = threading.Event()
        self.first_read_answered = threading.Event()
        self._lock = threading.Lock()
        self.service = self.node.create_service(Trigger, 'read', self._on_read,
                                                callback_group=ReentrantCallbackGroup())
        self.server = ActionServer(self.node, MoveTo, 'move_to', execute_callback=self._execute,
                                   goal_callback=self._on_goal,
                                   callback_group=ReentrantCallbackGroup())
        self.executor = MultiThreadedExecutor(num_threads=4, context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()

    def _on_goal(self, goal: MoveTo.Goal) -> GoalResponse:
        with self._lock:
            self.goals += 1
            first = self.goals == 1
        if first:
            time.sleep(self.hold)
            self.first_answered.set()
        return GoalResponse.ACCEPT

    def _on_read(self, request: Trigger.Request, response: Trigger.Response):
        """Answers its first call after ``hold`` seconds, each with its order of arrival."""
        with self._lock:
            self.reads += 1
            order = self.reads
        if order == 1:
            time.sleep(self.hold)
            self.first_read_answered.set()
        response.success, response.message = True, f'read {order}'
        return response

    def _execute(self, goal_handle) -> MoveTo.Result:
        with self._lock:
            order = self.goals
        goal_handle.succeed()
        with self._lock:
            self.executed += 1
        return MoveTo.Result(success=True, message=f'goal {order}')

    def all_executed(self) -> bool:
        """Every accepted goal has run: the server may go away without one still running
        (rcl_action then logs that the feedback publisher is invalid)."""
        with self._lock:
            return self.executed == self.goals

    def close(self) -> None:
        """Leave the domain (once; again is a no-op). The action server goes first: it holds
        the rcl node, which ``destroy_node`` leaves to it, so the DDS participant stayed
        until a garbage collection (as :meth:`RosTestClient.close` found for its clients)."""
        if not self.context.ok():
            return
        self.executor.shutdown(timeout_sec=1.0)
        self.server.destroy()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.mark.ros
def test_a_goal_not_accepted_in_time_is_sent_again(monkeypatch) -> None:
    monkeypatch.setattr(ros_testing, 'RESEND_S', 0.5)
    with DomainLease() as domain:
        server = SlowFirstAcceptServer(domain, hold=2.0)
        client = ros_testing.RosTestClient(domain)
        try:
            result, _, _ = client.run_action(MoveTo, '/move_to', MoveTo.Goal(), timeout=20.0)
            assert server.goals >= 2
            assert result.success and result.message != 'goal 1', result.message
            assert server.first_answered.wait(10.0)  # before the server goes away
            wait_for(server.all_executed, 10.0, 'the late-accepted first goal executed')
        finally:
            client.close()
            server.close()


@pytest.mark.ros
def test_a_goal_accepted_at_once_is_sent_once() -> None:
    with DomainLease() as domain:
        server = SlowFirstAcceptServer(domain, hold=0.0)
        client = ros_testing.RosTestClient(domain)
        try:
            result, _, _ = client.run_action(MoveTo, '/move_to', MoveTo.Goal(), timeout=20.0)
            assert (server.goals, result.message) == (1, 'goal 1')
            # A closed server leaves the domain before its lease goes: its action server
            # held the rcl node after destroy_node, and a test run beside this one that
            # leased the domain next refused to publish there (docs/testing.md).
            server.close()
            client.wait_for(lambda: 'slow_accept_server' not in client.node.get_node_names(),
                            30.0, 'the closed server to leave the domain')
        finally:
            client.close()
            server.close()


@pytest.mark.ros
@pytest.mark.parametrize('idempotent', [True, False])
def test_only_an_idempotent_call_is_sent_again(monkeypatch, idempotent: bool) -> None:
    monkeypatch.setattr(ros_testing, 'RESEND_S', 0.5)
    with DomainLease() as domain:
        server = SlowFirstAcceptServer(domain, hold=2.0)
        client = ros_testing.RosTestClient(domain)
        try:
            reply = client.call(Trigger, '/read', Trigger.Request(), timeout=20.0,
                                idempotent=idempotent)
            if idempotent:
                assert server.reads >= 2 and reply.message != 'read 1', reply.message
            else:
                assert (server.reads, reply.message) == (1, 'read 1')
            assert server.first_read_answered.wait(10.0)  # before the server goes away
        finally:
            client.close()
            server.close()


@pytest.mark.ros
def test_a_call_sent_once_first_lets_discovery_settle(monkeypatch) -> None:
    """The answer of a request sent once is lost if the service has not yet matched the
    client's reply reader: the first such call on a client waits, later ones do not, and a
    read-only service is resent instead of waiting."""
    settled: list[float] = []
    monkeypatch.setattr(ros_testing, 'settle_discovery', lambda: settled.append(1.0))
    with DomainLease() as domain:
        server = SlowFirstAcceptServer(domain, hold=0.0)
        client = ros_testing.RosTestClient(domain)
        try:
            names = client.call(ListParameters, '/slow_accept_server/list_parameters',
                                ListParameters.Request(), timeout=20.0)
            assert 'use_sim_time' in names.result.names
            assert settled == []
            assert client.call(Trigger, '/read', Trigger.Request(), timeout=20.0).success
            assert len(settled) == 1
            assert client.call(Trigger, '/read', Trigger.Request(), timeout=20.0).success
            assert len(settled) == 1
        finally:
            client.close()
            server.close()


@pytest.mark.ros
def test_unsubscribing_beside_a_busy_spin_keeps_the_client_spinning() -> None:
    """A subscription destroyed from the test's thread while the client's executor built its
    wait set raised InvalidHandle out of the spin, and the client went deaf for the rest of a
    module (docs/testing.md, the Capture node tests): unsubscribe now destroys it on the spin
    thread. 300 rounds beside a 1 kHz publisher ended the old spin within a few hundred."""
    with DomainLease() as domain:
        client = ros_testing.RosTestClient(domain)
        try:
            publisher = client.node.create_publisher(JointState, 'chatter', 10)
            timer = client.node.create_timer(0.001, lambda: publisher.publish(JointState()))
            for _ in range(300):
                client.subscribe('chatter', JointState)
                client.unsubscribe('chatter')
            client.node.destroy_timer(timer)
            client.check_spinning()
            # and it still receives
            received = client.subscribe('chatter', JointState)
            publisher.publish(JointState(name=['after']))
            wait_for(lambda: any(m.name == ['after'] for m in received), 10.0, 'the message')
        finally:
            client.close()


@pytest.mark.ros
def test_an_error_out_of_a_spin_is_kept_and_named_by_a_timed_out_wait() -> None:
    """A callback that raises no longer ends the spin thread silently: the spin goes on, and
    a wait that times out says what the executor raised."""
    def broken() -> None:
        raise ValueError('a broken callback')

    with DomainLease() as domain:
        client = ros_testing.RosTestClient(domain)
        try:
            client.executor.create_task(broken)
            wait_for(lambda: client.spin_errors, 10.0, 'the error to be kept')
            assert 'a broken callback' in client.spin_errors[0]
            with pytest.raises(TimeoutError,
                               match=r'(?s)executor raised 1 time.*a broken callback'):
                client.wait_for_message('nothing_here', JointState, timeout=0.5)
            client.spin_errors.clear()
            task = client.executor.create_task(lambda: 7)  # the thread goes on spinning
            wait_for(task.done, 10.0, 'a task after the error')
            assert task.result() == 7
        finally:
            client.close()
