"""The driver executable's main: construct, autostart, spin, stop cleanly on SIGINT/SIGTERM."""

from __future__ import annotations

import faulthandler
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, Protocol

import rclpy
from lifecycle_msgs.msg import State
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.context import Context
from rclpy.executors import (
    ConditionReachedException,
    Executor,
    ExternalShutdownException,
    ShutdownException,
    TimeoutException,
    TimeoutObject,
)
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future, Task

from gimbal_driver_common.ros.parameters import ParameterError

if TYPE_CHECKING:
    from gimbal_driver_common.ros.base_node import GimbalDriverNode

#: the signal on which a driver process writes every thread's stack to stderr (its log):
#: the test harness sends it to a node under test when a test fails
#: (gimbal_driver_testing.node_reports); ``kill -USR2 <pid>`` does it by hand.
#: Not SIGUSR1: tests/node_thread_probe.py has that one for its thread list.
THREAD_DUMP_SIGNAL = signal.SIGUSR2
#: Python thread switch interval in driver processes (default 5 ms)
GIL_SWITCH_INTERVAL_S = 0.001
#: seconds a shutting-down node waits for its action goals to answer their clients
GOAL_ANSWER_S = 3.0
#: names of the executor's pool threads (``executor-pool_0`` ...; ARCHITECTURE.md)
POOL_THREAD_PREFIX = 'executor-pool'


class NodeClass(Protocol):
    """A driver's node class: constructed with no arguments (its name is its own)."""

    __name__: str

    def __call__(self) -> GimbalDriverNode: ...


class InlineCallbackGroup(MutuallyExclusiveCallbackGroup):
    """A callback group whose callbacks :class:`InlineGroupExecutor` runs in its spinning
    thread (they never wait for a device reply)."""

    inline = True


def dump_threads(signum: int, frame: object) -> None:
    """Write every thread's stack to stderr (the node's log), on :data:`THREAD_DUMP_SIGNAL`.

    A Python-level handler, so it runs in the main thread holding the GIL while every other
    thread stands still. ``faulthandler.register`` dumps from the C signal handler instead,
    reading the other threads' frames while they run: a node under test died in the middle
    of such a dump under load (docs/testing.md). The main thread waits on an Event
    (:func:`run_driver`), so the handler runs at once.
    """
    faulthandler.dump_traceback(file=sys.stderr, all_threads=True)


def run_driver(node_class: NodeClass, args: Sequence[str] | None = None) -> int:
    """Entry point body for a driver executable: construct, autostart, spin, stop cleanly.

    rclpy's own SIGINT handler would shut the context down before ``on_shutdown`` runs,
    losing the "axes stopped" log and any last message; so signals are handled here. The
    executor spins in a worker thread and the main thread waits on an Event, which (unlike
    a blocking rcl_wait) lets the Python signal handler run at once.
    """
    # first, so that a process that hangs anywhere later can still say where
    signal.signal(THREAD_DUMP_SIGNAL, dump_threads)
    rclpy.init(args=None if args is None else list(args),
               signal_handler_options=SignalHandlerOptions.NO)
    # The device thread must not wait the default 5 ms for the GIL while a receive thread
    # (e.g. python-can's byte-wise slcan reader) is busy: that showed as joint_states latency.
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    stop = threading.Event()

    def request_stop(signum: int, frame: object) -> None:
        stop.set()

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)  # launch sends SIGTERM after SIGINT
    try:
        node = node_class()
    except ParameterError as exc:
        rclpy.logging.get_logger(node_class.__name__).fatal(f'invalid parameter: {exc}')
        rclpy.try_shutdown()
        return 2
    executor = InlineGroupExecutor(num_threads=4)
    executor.add_node(node)
    spinner = threading.Thread(target=_spin, args=(executor, stop), name='executor',
                               daemon=True)
    spinner.start()
    if node.autostart:
        threading.Thread(target=_autostart, args=(node,), name='autostart', daemon=True).start()
    while not stop.wait(1.0):
        pass
    # the shutdown transition's callback, run here by hand (it does not read its state)
    node.on_shutdown(LifecycleState('shuttingdown', State.TRANSITION_STATE_SHUTTINGDOWN))
    answer_open_goals(node, executor)
    # The executor stops before the node is destroyed: destroying it under a spinning
    # executor raced the wait-set build (InvalidHandle from an event handler's
    # add_to_wait_set, a traceback the U-Camera soak caught at shutdown).
    executor.shutdown(timeout_sec=1.0)
    spinner.join(timeout=2.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def answer_open_goals(node: GimbalDriverNode, executor: Executor,
                      timeout: float = GOAL_ANSWER_S) -> bool:
    """Let the goals the shutdown ended send their results before the executor stops.

    The halt ends every running goal. rclpy then sends each result from a task of its
    own, which the goal's task queues once the execute callback returned. So: wait for the
    execute callbacks, then for the pool tasks that ran them, then for the executor to
    take a task queued after the result sends (it takes tasks in the order they were made)
    and for the pool to finish them; then, while the result request of a goal accepted
    just before may still be on its way (:meth:`OpenGoals.result_request_due`), go on
    spinning. False, with a warning, after ``timeout`` seconds.
    """
    deadline = time.monotonic() + timeout

    def pool_tasks() -> list[Task]:
        return list(executor.running) if isinstance(executor, InlineGroupExecutor) else []

    def until(condition: Callable[[], bool]) -> bool:
        while not condition():
            if time.monotonic() > deadline:
                return False
            time.sleep(0.005)
        return True

    node.open_goals.close()  # a goal from now on is rejected: answered at once
    if not node.open_goals.wait_ended(timeout):
        node.get_logger().warning(
            f'{node.open_goals.count} action goal(s) still running {timeout:g} s after the '
            'shutdown began: their clients get no result')
        return False
    goal_tasks = pool_tasks()
    if not until(lambda: all(task.done() for task in goal_tasks)):
        return False
    marker = executor.create_task(lambda: None)
    if not until(marker.done):
        return False
    sends = pool_tasks()
    if not until(lambda: all(task.done() for task in sends)):
        return False
    # A goal accepted just before the shutdown: its client's result request may still be
    # on its way. The executor keeps spinning, and answers it from the stored result.
    return until(lambda: node.open_goals.result_request_due() == 0.0)


def _spin(executor: Executor, stop: threading.Event) -> None:
    try:
        executor.spin()
    except (ExternalShutdownException, KeyboardInterrupt):
        pass
    finally:
        stop.set()


def _autostart(node: GimbalDriverNode) -> None:
    """Configure (retrying while the device is absent) and activate."""
    logger = node.get_logger()
    while rclpy.ok():
        state = node.lifecycle_state
        if state == 'unconfigured':
            if node.trigger_configure() == TransitionCallbackReturn.SUCCESS:
                continue
            logger.warning(f'autostart: retrying configure in {node.reconnect_period:g} s')
            time.sleep(node.reconnect_period)
        elif state == 'inactive':
            node.trigger_activate()
            return
        else:
            return


class InlineGroupExecutor(Executor):
    """An executor that runs the callbacks of an *inline* callback group in its spinning
    thread and every other callback in a pool, like ``MultiThreadedExecutor``.

    Written on rclpy's public extension point (``spin_once`` over
    ``wait_for_ready_callbacks``, as :class:`rclpy.executors.Executor` asks of a custom
    executor) with a pool of its own. Measured (bench, node trace): the hand-off to a
    pool thread is the whole of the command path's excess over a bare rclpy subscriber
    (publish -> callback p50 1.7 ms against 0.65 ms single-threaded). ``joint_command``'s
    callback never waits for a device reply, so it runs inline; services and actions run
    in the pool, so ``~/stop`` answers while a ``move_to`` waits.
    """

    def __init__(self, num_threads: int = 4, *, context: Context | None = None) -> None:
        super().__init__(context=context)
        self.pool = ThreadPoolExecutor(num_threads, thread_name_prefix=POOL_THREAD_PREFIX)
        self.running: list[Task] = []
        #: set by :meth:`shutdown`: a pool task that fails from then on failed because the
        #: executor's guard condition went away under it (rclpy's task epilogue triggers
        #: it), not because of its callback
        self.closing = False

    def spin_once(self, timeout_sec: float | None = None) -> None:
        self.run_one(timeout_sec)

    def spin_once_until_future_complete(
            self, future: Future, timeout_sec: float | TimeoutObject | None = None) -> None:
        future.add_done_callback(lambda _: self.wake())
        self.run_one(timeout_sec, future.done)

    def run_one(self, timeout_sec: float | TimeoutObject | None = None,
                wait_condition: Callable[[], bool] = lambda: False) -> None:
        """Wait for one ready callback and run it inline or hand it to the pool."""
        entity: object  # a subscription, service, timer ... (rclpy types it as a TypeVar)
        try:
            handler, entity, _ = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (ExternalShutdownException, ShutdownException, TimeoutException,
                ConditionReachedException):
            return
        if getattr(getattr(entity, 'callback_group', None), 'inline', False):
            handler()
            if not self.closing:
                handler.result()  # raise what the callback raised, as the pool path does
            return
        self.pool.submit(handler)
        self.running.append(handler)
        for task in [task for task in self.running if task.done()]:
            self.running.remove(task)
            if not self.closing:
                task.result()

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        self.closing = True
        done = super().shutdown(timeout_sec)
        self.pool.shutdown(wait=False, cancel_futures=True)
        return done
