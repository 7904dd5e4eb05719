"""run_driver's executor: an inline callback group runs in the spinning thread, every other
callback in the executor's named pool (public rclpy only)."""

from __future__ import annotations

import threading

import pytest
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

from gimbal_driver_common.ros.run import POOL_THREAD_PREFIX, InlineGroupExecutor
from gimbal_driver_testing import DomainLease, wait_for

pytestmark = pytest.mark.ros


def test_inline_group_runs_in_the_spinning_thread_and_the_rest_in_the_pool() -> None:
    with DomainLease() as domain:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        node = Node('executor_test', context=context)
        executor = InlineGroupExecutor(num_threads=2, context=context)
        ran: dict[str, set[str]] = {'inline': set(), 'pool': set()}
        inline_group = MutuallyExclusiveCallbackGroup()
        inline_group.inline = True
        node.create_timer(0.01, lambda: ran['inline'].add(threading.current_thread().name),
                          callback_group=inline_group)
        node.create_timer(0.01, lambda: ran['pool'].add(threading.current_thread().name))
        executor.add_node(node)
        spinner = threading.Thread(target=executor.spin, name='spinning', daemon=True)
        spinner.start()
        try:
            wait_for(lambda: ran['inline'] and ran['pool'], 10, 'both timers')
        finally:
            executor.shutdown(timeout_sec=1.0)
            spinner.join(timeout=2.0)
            node.destroy_node()
            rclpy.shutdown(context=context)
        assert ran['inline'] == {'spinning'}
        assert ran['pool'] and all(name.startswith(f'{POOL_THREAD_PREFIX}_')
                                   for name in ran['pool'])
        assert not spinner.is_alive()
