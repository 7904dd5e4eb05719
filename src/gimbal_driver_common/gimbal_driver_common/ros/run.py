"""The driver executable's main: construct, autostart, spin, stop cleanly on SIGINT/SIGTERM."""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.signals import SignalHandlerOptions

from gimbal_driver_common.ros.parameters import ParameterError

if TYPE_CHECKING:
    from gimbal_driver_common.ros.base_node import GimbalDriverNode

#: Python thread switch interval in driver processes (default 5 ms)
GIL_SWITCH_INTERVAL_S = 0.001


def run_driver(node_class: type[GimbalDriverNode], args: Sequence[str] | None = None) -> int:
    """Entry point body for a driver executable: construct, autostart, spin, stop cleanly.

    rclpy's own SIGINT handler would shut the context down before ``on_shutdown`` runs,
    losing the "axes stopped" log and any last message; so signals are handled here. The
    executor spins in a worker thread and the main thread waits on an Event, which (unlike
    a blocking rcl_wait) lets the Python signal handler run at once.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
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
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    spinner = threading.Thread(target=_spin, args=(executor, stop), name='executor',
                               daemon=True)
    spinner.start()
    if node.autostart:
        threading.Thread(target=_autostart, args=(node,), daemon=True).start()
    while not stop.wait(1.0):
        pass
    node.on_shutdown(None)
    node.destroy_node()
    executor.shutdown(timeout_sec=1.0)
    rclpy.try_shutdown()
    spinner.join(timeout=2.0)
    return 0


def _spin(executor: MultiThreadedExecutor, stop: threading.Event) -> None:
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
        state = node._state_machine.current_state[1]
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
