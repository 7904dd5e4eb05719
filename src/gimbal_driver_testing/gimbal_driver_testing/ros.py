"""An rclpy test client in its own context and domain, for node-as-a-process tests."""

from __future__ import annotations

import contextlib
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, NoReturn, TypeVar

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import (
    DescribeParameters,
    GetParameters,
    GetParameterTypes,
    ListParameters,
    SetParameters,
)
from rclpy.action import ActionClient
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from gimbal_driver_testing import (
    DomainLease,
    ManagedProcess,
    attach_report,
    ros_arguments,
    wait_for,
)
from gimbal_driver_testing.graph_guard import refuse_foreign_nodes
from gimbal_msgs.srv import ListPresets

T = TypeVar('T')


def joint_positions(msg: JointState) -> dict[str, float]:
    """Joint name -> position of a JointState."""
    return dict(zip(msg.name, msg.position, strict=True))


def find_diagnostic(array: DiagnosticArray, node: str, part: str) -> DiagnosticStatus | None:
    """The status named ``<node>: <part>`` in a DiagnosticArray, or None."""
    for status in array.status:
        if status.name == f'{node}: {part}':
            return status
    return None


# Generated message modules import their nested types lazily; two threads doing that
# for the first time at once can fail ("not an instance of 'capsule'"), so entity
# creation is serialised.
_TYPE_SUPPORT_LOCK = threading.Lock()

# How long an idempotent service call waits for its reply, or an action client for its
# goal to be accepted, before sending the request again.
RESEND_S = 3.0

# How long a new publisher, or a service client whose request is not resent, waits once it
# sees the other side before it sends. Discovery is not symmetric: this side can match the
# other's endpoint before the other has matched this side's, and what is sent then is lost:
# a message on a volatile topic, or a service's answer (see :func:`newest_answered`; one
# full CI run lost the answer of a ~/start_scan sent at once, and the node logged "failed to
# send response (timeout): client will not receive response"). Neither side's view of the
# other is observable from here, so this is a wait, not a condition.
DISCOVERY_SETTLE_S = 0.5


def settle_discovery() -> None:
    """Give the other side :data:`DISCOVERY_SETTLE_S` to match this side's new endpoint."""
    time.sleep(DISCOVERY_SETTLE_S)


# Services that only read: their requests are always resent (``idempotent``).
READ_ONLY_SERVICES: tuple[type, ...] = (
    DescribeParameters, GetParameters, GetParameterTypes, ListParameters, GetState,
    ListPresets,
)


def newest_answered(send: Callable[[], Any], timeout: float, what: str,
                    resend: bool) -> Any:
    """The future of the newest request ``send()`` made, once done. With ``resend``, a
    request not answered within :data:`RESEND_S` is sent again: its answer may be lost.
    rmw_fastrtps' ``__rmw_send_response`` (rmw_fastrtps_shared_cpp
    ``src/rmw_response.cpp``) waits only the writer's ``max_blocking_time`` for the server
    to match this client's reader, then drops the answer ("failed to send response
    (timeout): client will not receive response"); ``wait_for_service`` and
    ``wait_for_server`` only say that this side has matched."""
    deadline, sent = time.monotonic() + timeout, 0
    while True:
        future = send()
        sent += 1
        left = deadline - time.monotonic()
        try:
            wait_for(future.done, max(0.0, min(RESEND_S, left) if resend else left), what)
            return future
        except TimeoutError:
            if not resend or left <= RESEND_S:
                raise TimeoutError(f'timed out after {timeout:g} s waiting for {what} '
                                   f'({sent} sent)') from None


class RosTestClient:
    """Publishes, subscribes, calls services and actions against nodes in ``domain_id``.

    It commands only what the test started: before the first publish on a topic, the first
    call of a service that is not read-only and each action goal it reads the graph and
    raises :class:`~gimbal_driver_testing.graph_guard.ForeignNodesError` while a node of a
    process outside the test run is on the domain (:mod:`gimbal_driver_testing.graph_guard`).
    """

    def __init__(self, domain_id: int, name: str = 'gimbal_test_client') -> None:
        self.domain_id = domain_id
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        # One thread: callbacks only record; rclpy's MultiThreadedExecutor spins hot on
        # the GIL while a worker has not yet taken a ready message, delaying messages.
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._closing = threading.Event()
        #: tracebacks of errors out of a spin (:meth:`_spin`)
        self.spin_errors: list[str] = []
        self._thread = threading.Thread(target=self._spin, daemon=True, name=f'{name}-spin')
        self._thread.start()
        self._messages: dict[str, list[Any]] = {}
        self._subscriptions: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._publishers: dict[str, Any] = {}
        self._clients: dict[tuple[type, str], Any] = {}
        # clients that have had an answer: the service has matched their reply reader
        self._answered_clients: set[tuple[type, str]] = set()

    def _spin(self) -> None:
        """Spin until closed. An error out of one spin (a callback's, or rclpy's wait-set
        build) is kept in :attr:`spin_errors` and the spin goes on: the thread used to end
        silently on the first one, and the client then got no message and no answer, which
        failed every later test of a module as "no matching joint_states", "no reply"."""
        while not self._closing.is_set():
            try:
                self.executor.spin_once()  # executor.shutdown() wakes it
            except Exception as exc:  # noqa: BLE001 - kept and reported, see above
                if self._closing.is_set():
                    return  # shutdown races end the spin with assorted errors
                self.spin_errors.append(''.join(traceback.format_exception(exc)))

    def check_spinning(self) -> None:
        """Raise if the spin thread has ended or an error came out of a spin (the waits
        call it when they time out, so the failure names the cause)."""
        if self.spin_errors:
            raise RuntimeError(f'the test client\'s executor raised {len(self.spin_errors)} '
                               f'time(s); the first:\n{self.spin_errors[0]}')
        if not self._thread.is_alive() and not self._closing.is_set():
            raise RuntimeError('the test client\'s spin thread has ended')

    def _wait(self, condition: Callable[[], Any], timeout: float, what: str) -> Any:
        """:func:`wait_for`, naming a broken client (:meth:`check_spinning`) on a timeout."""
        try:
            return wait_for(condition, timeout, what)
        except TimeoutError as exc:
            self._timed_out(exc)

    def _timed_out(self, exc: TimeoutError) -> NoReturn:
        """Raise ``exc``, with what broke this client if it is broken."""
        try:
            self.check_spinning()
        except RuntimeError as broken:
            raise TimeoutError(f'{exc}: {broken}') from None
        raise exc

    def close(self) -> None:
        """Leave the domain. The action clients go first: ``destroy_node`` leaves them, and
        each holds the rcl node, so the DDS participant lived on after the lease was
        released until a garbage collection, and the next test on the domain saw it (in
        another worker: a ForeignNodesError naming this client)."""
        self._closing.set()
        self.executor.shutdown(timeout_sec=1.0)
        for client in self._clients.values():
            if isinstance(client, ActionClient):
                client.destroy()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
        self._thread.join(timeout=2.0)

    def __enter__(self) -> RosTestClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # topics
    @staticmethod
    def wait_for(condition: Callable[[], T], timeout: float = 10.0, what: str = 'condition',
                 interval: float = 0.02) -> T:
        """:func:`gimbal_driver_testing.wait_for`, for code handed the client that imports
        nothing of this package (a driver's demo steps, which are installed with it)."""
        return wait_for(condition, timeout, what, interval)

    def subscribe(self, topic: str, msg_type: type, reliable: bool = True) -> list[Any]:
        """Start recording ``topic``; returns the live list of received messages."""
        with self._lock:
            if topic in self._messages:
                return self._messages[topic]
            received: list[Any] = []
            self._messages[topic] = received
        qos = QoSProfile(
            depth=100,
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        )

        def record(msg: Any) -> None:
            with self._lock:
                received.append(msg)

        with _TYPE_SUPPORT_LOCK:
            self._subscriptions[topic] = self.node.create_subscription(
                msg_type, topic, record, qos)
        return received

    def unsubscribe(self, topic: str) -> None:
        """Stop recording ``topic`` and destroy the subscription (no-op if none).

        Destroyed on the spin thread, between two waits: destroyed from another thread, its
        QoS event handler can be destroyed while the executor adds it to the wait set, and
        rclpy raises ``InvalidHandle`` out of the spin (``EventHandler.add_to_wait_set``;
        reproduced: a subscription made and destroyed every 2 ms beside a spinning
        executor ended the spin within seconds, on the spin thread never in 15 s). That
        ended this client's spin thread in a Capture node test (docs/testing.md).
        """
        with self._lock:
            self._messages.pop(topic, None)
            subscription = self._subscriptions.pop(topic, None)
        if subscription is not None:
            self._on_spin_thread(lambda: self.node.destroy_subscription(subscription), 15.0,
                                 f'the executor to destroy the {topic} subscription')

    def wait_for_message(
        self, topic: str, msg_type: type, predicate: Callable[[Any], bool] | None = None,
        timeout: float = 15.0, fresh: bool = True, since: int | None = None,
    ) -> Any:
        """Wait for a message on ``topic`` matching ``predicate`` (only new ones if ``fresh``;
        ``since``: from that index of the recorded list on, for a state that may have come
        and gone before the wait began)."""
        received = self.subscribe(topic, msg_type)
        start = since if since is not None else len(received) if fresh else 0

        def match() -> Any:
            with self._lock:
                for msg in received[start:]:
                    if predicate is None or predicate(msg):
                        return msg
            return None

        return self._wait(match, timeout, f'a matching message on {topic}')

    def wait_for_diagnostic(
        self, node: str, part: str,
        predicate: Callable[[DiagnosticStatus], bool] | None = None, timeout: float = 15.0,
        since: int | None = None,
    ) -> DiagnosticStatus:
        """Wait for a new ``<node>: <part>`` status on /diagnostics matching ``predicate``
        (``since``: recorded from that index on, see :meth:`wait_for_message`)."""

        def match(array: DiagnosticArray) -> bool:
            status = find_diagnostic(array, node, part)
            return status is not None and (predicate is None or predicate(status))

        array = self.wait_for_message('/diagnostics', DiagnosticArray, match, timeout,
                                      since=since)
        return find_diagnostic(array, node, part)

    def mean_stamp_gap(self, topic: str, msg_type: type, count: int,
                       timeout: float = 60.0) -> float:
        """Mean gap between the header stamps of ``count`` + 1 fresh messages, in s.

        Stamps are set where the data arrived, so the gaps show the rate the node
        produces, not the delivery jitter of a loaded machine.
        """
        received = self.subscribe(topic, msg_type)
        with self._lock:
            start = len(received)
        self._wait(lambda: len(received) >= start + count + 1, timeout,
                   f'{count + 1} messages on {topic}')
        with self._lock:
            stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
                      for m in received[start:start + count + 1]]
        return (stamps[-1] - stamps[0]) / count

    def publish(self, topic: str, msg: Any) -> None:
        publisher = self._publishers.get(topic)
        if publisher is None:
            with _TYPE_SUPPORT_LOCK:
                publisher = self.node.create_publisher(type(msg), topic, 10)
            self._publishers[topic] = publisher
            wait_for(lambda: publisher.get_subscription_count() > 0, 10.0,
                     f'a subscriber on {topic}')
            settle_discovery()  # the subscriber may not have matched it yet
            refuse_foreign_nodes(self.node, self.domain_id, f'publish on {topic}')
        publisher.publish(msg)

    def subscribers_matched(self, topic: str, count: int, timeout: float = 30.0) -> None:
        """Wait until this client's publisher on ``topic`` (if it has one) has ``count``
        subscriptions matched, then :data:`DISCOVERY_SETTLE_S` when ``count`` > 0: around a
        node's restart (0 once the old one is gone, 1 when the new one came), so that the
        first message to the new node is not lost to its discovery."""
        publisher = self._publishers.get(topic)
        if publisher is None:
            return  # publish() makes it and waits for the subscriber itself
        self._wait(lambda: publisher.get_subscription_count() == count, timeout,
                   f'{count} subscriber(s) on {topic}')
        if count:
            settle_discovery()

    # services
    def call(self, srv_type: type, name: str, request: Any, timeout: float = 15.0,
             idempotent: bool = False) -> Any:
        """Call a service and return its reply.

        ``idempotent``: send the request again every :data:`RESEND_S` while no reply came
        (:func:`newest_answered`; for reads such as the parameter services: seen once in five
        full runs, list_parameters never answered). Only a request that may run twice is
        resent; :data:`READ_ONLY_SERVICES` always are. The first request that is not, on a
        client that has had no answer yet, waits :data:`DISCOVERY_SETTLE_S` first.
        """
        idempotent = idempotent or issubclass(srv_type, READ_ONLY_SERVICES)
        # Clients are kept, not destroyed: destroying an entity while the executor
        # thread waits on it can end the spin.
        client = self._clients.get((srv_type, name))
        if client is None:
            with _TYPE_SUPPORT_LOCK:
                client = self.node.create_client(srv_type, name)
            self._clients[(srv_type, name)] = client
        if not client.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f'service {name} not available after {timeout:g} s')
        if not idempotent and (srv_type, name) not in self._answered_clients:
            settle_discovery()
            refuse_foreign_nodes(self.node, self.domain_id, f'call {name}')
        try:
            reply = newest_answered(lambda: client.call_async(request), timeout,
                                    f'the reply of {name}', resend=idempotent)
        except TimeoutError as exc:
            self._timed_out(exc)
        self._answered_clients.add((srv_type, name))
        return reply.result()

    # parameters (what `ros2 param set/get` do: the node's parameter services)
    def set_parameter(
        self, node_name: str, name: str, value: Any, timeout: float = 15.0
    ) -> SetParametersResult:
        """Set one parameter of ``node_name``; returns rclpy's (successful, reason)."""
        request = SetParameters.Request(parameters=[Parameter(name, value=value)
                                                    .to_parameter_msg()])
        return self.call(SetParameters, f'/{node_name}/set_parameters', request,
                         timeout, idempotent=True).results[0]

    def get_parameter(self, node_name: str, name: str, timeout: float = 15.0) -> Any:
        reply = self.call(GetParameters, f'/{node_name}/get_parameters',
                          GetParameters.Request(names=[name]), timeout)
        return parameter_value_to_python(reply.values[0])

    # actions
    def run_action(
        self, action_type: type, name: str, goal: Any, timeout: float = 30.0,
        cancel_after: float | None = None,
    ) -> tuple[Any, int, list[Any]]:
        """Send a goal and wait for its result: (result, status, feedback messages).

        A goal not accepted within :data:`RESEND_S` is sent again, and the newest one sent
        is the one waited for (:func:`newest_answered`: the first goal of a new client can
        be accepted and its answer lost, seen in the demo under the parallel suite). The
        drivers' action servers accept every goal and a newer one supersedes the older, so
        the goal runs once, as the newest.
        """
        client = self._clients.get((action_type, name))
        new = client is None
        if client is None:
            with _TYPE_SUPPORT_LOCK:
                client = ActionClient(self.node, action_type, name)
            self._clients[(action_type, name)] = client
        if not client.wait_for_server(timeout_sec=timeout):
            raise TimeoutError(f'action {name} not available after {timeout:g} s')
        refuse_foreign_nodes(self.node, self.domain_id, f'send a goal to {name}')
        if new:
            # wait_for_server sees the goal, cancel and result services; the feedback
            # topic is matched on its own, and a goal that ends at once (already at its
            # target) may publish its only feedback before that: wait until this side
            # has discovered the server's feedback writer
            feedback_topic = f'{name}/_action/feedback'
            self._wait(lambda: self.node.count_publishers(feedback_topic) > 0, timeout,
                       f'the feedback publisher of {name}')
        received: list[list[Any]] = []  # each goal's feedback

        def send_goal() -> Any:
            feedback: list[Any] = []
            received.append(feedback)
            return self._on_spin_thread(
                lambda: client.send_goal_async(
                    goal, feedback_callback=lambda f: feedback.append(f.feedback)),
                timeout, f'{name} to send the goal')

        try:
            send = newest_answered(send_goal, timeout, f'{name} to accept the goal',
                                   resend=True)
        except TimeoutError as exc:
            self._timed_out(exc)
        feedback = received[-1]
        handle = send.result()
        if not handle.accepted:
            raise AssertionError(f'{name} rejected the goal')
        if cancel_after is not None:
            time.sleep(cancel_after)
            cancel = self._on_spin_thread(handle.cancel_goal_async, timeout, 'the cancel')
            self._wait(cancel.done, timeout, f'{name} to answer the cancel')
        result_future = self._on_spin_thread(handle.get_result_async, timeout, 'the request')
        self._wait(result_future.done, timeout, f'the result of {name}')
        response = result_future.result()
        return response.result, response.status, feedback

    def _on_spin_thread(self, request: Callable[[], Any], timeout: float, what: str) -> Any:
        """Call ``request`` (an ActionClient ``*_async``) on the executor's thread.

        rclpy#1123: an answer that the spin thread takes before ``*_async`` has stored
        its future is dropped ("Ignoring unexpected goal response"), and the future never
        completes. Called from the (single) spin thread, the answer waits until it has.
        """
        task = self.executor.create_task(request)
        self._wait(task.done, timeout, f'the executor to run {what}')
        return task.result()

    # lifecycle
    def lifecycle_state(self, node_name: str, timeout: float = 15.0) -> str:
        reply = self.call(GetState, f'/{node_name}/get_state', GetState.Request(), timeout)
        return reply.current_state.label

    def lifecycle_transition(self, node_name: str, transition: int, timeout: float = 15.0) -> bool:
        request = ChangeState.Request(transition=Transition(id=transition))
        return self.call(ChangeState, f'/{node_name}/change_state', request, timeout).success

    def wait_for_lifecycle_state(self, node_name: str, label: str, timeout: float = 30.0) -> None:
        def reached() -> bool:
            try:
                return self.lifecycle_state(node_name, timeout=2.0) == label
            except TimeoutError:
                return False

        wait_for(reached, timeout, f'{node_name} to reach lifecycle state {label!r}', 0.2)


@dataclass
class DriverRig:
    """A simulator process, a driver node process and a test client in one leased domain."""

    ros: RosTestClient
    node: ManagedProcess
    sim: ManagedProcess
    domain: int
    recorded: dict[str, list[Any]] = field(default_factory=dict)  # topic -> messages


@contextlib.contextmanager
def driver_rig(
    package: str, sim_executable: str, sim_arguments: Sequence[str],
    sim_ready: str | Callable[[ManagedProcess], None], node_executable: str,
    node_parameters: Sequence[str] | Callable[[ManagedProcess], Sequence[str]],
    client_name: str = 'gimbal_test_client', record: Sequence[tuple[str, type]] = (),
    node_log_tail: int = 0,
) -> Iterator[DriverRig]:
    """Start the simulator, wait until it is ready (``sim_ready``: a text it prints, or a
    function that waits), start the node with ``name:=value`` parameters (or a function of
    the ready simulator that gives them, e.g. the pty it printed), and yield once the first
    joint_states arrived; stops everything on exit.

    ``record``: (topic, type) pairs subscribed before the first joint_states, so what the
    node says while it starts is kept (``DriverRig.recorded``). ``node_log_tail``: that many
    characters of the node's output are printed at the end (pytest shows them on failure).
    """
    with DomainLease() as domain:
        sim = ManagedProcess.ros(package, sim_executable, domain, sim_arguments)
        node = ros = None
        try:
            if isinstance(sim_ready, str):
                sim.wait_for_output(sim_ready, timeout=30.0)
            else:
                sim_ready(sim)
            parameters = node_parameters(sim) if callable(node_parameters) else node_parameters
            node = ManagedProcess.ros(package, node_executable, domain, ros_arguments(parameters))
            ros = RosTestClient(domain, client_name)
            recorded = {topic: ros.subscribe(topic, msg_type) for topic, msg_type in record}
            ros.wait_for_message('joint_states', JointState, timeout=40.0)
            yield DriverRig(ros, node, sim, domain, recorded)
        except Exception as exc:
            if node is not None:
                attach_report(exc, node)  # before it stops: where its threads are
            raise
        finally:
            if ros is not None:
                ros.close()
            if node is not None:
                node.stop()
                if node_log_tail:
                    print('--- node log (tail) ---\n' + node.output()[-node_log_tail:])
            sim.stop()


def node_refusing_to_start(package: str, node_executable: str, node_parameters: Sequence[str],
                           timeout: float = 30.0) -> str:
    """Start the node with ``name:=value`` parameters that it must refuse, wait until it
    has exited with a failure, and return what it printed (to look for the name)."""
    with DomainLease() as domain:
        node = ManagedProcess.ros(package, node_executable, domain,
                                  ros_arguments(node_parameters))
        try:
            wait_for(lambda: not node.running, timeout,
                     f'{node_executable} to refuse {list(node_parameters)}')
        finally:
            node.stop()
    assert node.process.returncode != 0, f'{node_executable} exited with 0:\n{node.output()}'
    return node.output()
