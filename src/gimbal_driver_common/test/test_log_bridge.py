"""The Python logging -> ROS logger bridge (ros/log_bridge.py): severities, names, levels,
threads, one line per record, no loop; and a real node's /rosout."""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator

import pytest
import rclpy
from rcl_interfaces.msg import Log
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from gimbal_driver_common.ros.base_node import GimbalDriverNode
from gimbal_driver_common.ros.log_bridge import (
    CORE_LOGGER,
    bridged_loggers,
    install_log_bridge,
)
from gimbal_driver_testing import DomainLease, wait_for

PACKAGE = 'fake_driver_pkg'


class FakeNodeLogger:
    """Records (severity, text) like rclpy's RcutilsLogger would log them."""

    def __init__(self, name: str = 'fake_node', level: int = 20) -> None:
        self.name = name
        self.level = level
        self.lines: list[tuple[str, str]] = []
        self.on_log = lambda: None

    def get_effective_level(self) -> int:
        return self.level

    def _log(self, severity: str, message: str) -> bool:
        self.lines.append((severity, message))
        self.on_log()
        return True

    def debug(self, message: str) -> bool:
        return self._log('debug', message)

    def info(self, message: str) -> bool:
        return self._log('info', message)

    def warning(self, message: str) -> bool:
        return self._log('warn', message)

    def error(self, message: str) -> bool:
        return self._log('error', message)

    def fatal(self, message: str) -> bool:
        return self._log('fatal', message)


@pytest.fixture
def node_logger() -> Iterator[FakeNodeLogger]:
    logger = FakeNodeLogger()
    bridge = install_log_bridge(logger, f'{PACKAGE}.node')
    try:
        yield logger
    finally:
        bridge.remove()


def test_the_core_and_the_driver_package_are_bridged_once() -> None:
    assert bridged_loggers('capture_driver.node') == [CORE_LOGGER, 'capture_driver']
    assert bridged_loggers('gimbal_driver_common.ros.base_node', ['can', 'can']) == [
        CORE_LOGGER, 'can']


def test_each_level_maps_to_its_ros_severity_with_the_logger_name(node_logger) -> None:
    log = logging.getLogger(f'{PACKAGE}.client')
    log.setLevel(logging.DEBUG)
    try:
        log.debug('d %d', 1)
        log.info('i')
        log.warning('w')
        log.error('e')
        log.critical('c')
    finally:
        log.setLevel(logging.NOTSET)
    name = f'{PACKAGE}.client'
    assert node_logger.lines == [('debug', f'{name}: d 1'), ('info', f'{name}: i'),
                                 ('warn', f'{name}: w'), ('error', f'{name}: e'),
                                 ('fatal', f'{name}: c')]


def test_info_passes_the_package_level_and_the_core_is_bridged_too(node_logger) -> None:
    # without the bridge the package logger inherits the root's WARNING: INFO is dropped
    logging.getLogger('gimbal_driver_common.session').info('link open')
    logging.getLogger(f'{PACKAGE}.device').debug('below the node level: not forwarded')
    assert node_logger.lines == [('info', 'gimbal_driver_common.session: link open')]


def test_an_exception_keeps_its_traceback(node_logger) -> None:
    try:
        raise ValueError('bad frame')
    except ValueError:
        logging.getLogger(f'{PACKAGE}.client').exception('handler failed')
    severity, text = node_logger.lines[-1]
    assert severity == 'error' and 'handler failed' in text and 'ValueError: bad frame' in text


def test_other_loggers_are_left_alone(node_logger) -> None:
    logging.getLogger('someone_else').warning('not ours')
    logging.getLogger('fake_driver_pkg_other').warning('not ours either')
    assert node_logger.lines == []


def test_removed_restores_the_level_and_forwards_nothing(caplog) -> None:
    logger = FakeNodeLogger()
    package = logging.getLogger(PACKAGE)
    assert package.level == logging.NOTSET
    bridge = install_log_bridge(logger, PACKAGE)
    assert package.level == logging.INFO and bridge.installed
    bridge.remove()
    bridge.remove()  # idempotent
    assert package.level == logging.NOTSET and not bridge.installed
    logging.getLogger(f'{PACKAGE}.client').warning('after')
    assert logger.lines == []


def test_an_explicit_level_is_kept() -> None:
    package = logging.getLogger(PACKAGE)
    package.setLevel(logging.ERROR)
    logger = FakeNodeLogger()
    bridge = install_log_bridge(logger, PACKAGE)
    try:
        logging.getLogger(f'{PACKAGE}.client').warning('dropped by the explicit level')
        assert logger.lines == [] and package.level == logging.ERROR
    finally:
        bridge.remove()
        package.setLevel(logging.NOTSET)
    assert package.level == logging.NOTSET


def test_the_node_level_sets_the_package_level() -> None:
    logger = FakeNodeLogger(level=10)  # --log-level debug
    bridge = install_log_bridge(logger, PACKAGE)
    try:
        logging.getLogger(f'{PACKAGE}.client').debug('seen')
        assert logger.lines == [('debug', f'{PACKAGE}.client: seen')]
    finally:
        bridge.remove()


def test_a_second_bridge_takes_over_and_hands_back_one_line_per_record() -> None:
    first, second = FakeNodeLogger('first'), FakeNodeLogger('second')
    bridge_1 = install_log_bridge(first, PACKAGE)
    bridge_2 = install_log_bridge(second, PACKAGE)
    log = logging.getLogger(f'{PACKAGE}.client')
    try:
        log.warning('one')
        assert (first.lines, second.lines) == ([], [('warn', f'{PACKAGE}.client: one')])
        bridge_2.remove()
        log.warning('two')
        assert first.lines == [('warn', f'{PACKAGE}.client: two')]
        assert len(second.lines) == 1
    finally:
        bridge_2.remove()
        bridge_1.remove()
    assert logging.getLogger(PACKAGE).handlers == []


def test_records_from_many_threads_arrive_once_each_whole(node_logger) -> None:
    threads, per_thread = 8, 200
    barrier = threading.Barrier(threads)

    def work(index: int) -> None:
        log = logging.getLogger(f'{PACKAGE}.reader{index}')
        barrier.wait()
        for i in range(per_thread):
            log.warning('thread %d line %d', index, i)

    workers = [threading.Thread(target=work, args=(n,)) for n in range(threads)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join()
    expected = {f'{PACKAGE}.reader{n}: thread {n} line {i}'
                for n in range(threads) for i in range(per_thread)}
    texts = [text for _, text in node_logger.lines]
    assert len(texts) == len(expected) and set(texts) == expected


def test_a_record_logged_while_forwarding_does_not_loop(node_logger, capsys) -> None:
    """rcutils (or an output handler) logging through Python logging again: printed to
    stderr once, not forwarded again."""
    nested = logging.getLogger(f'{PACKAGE}.rcutils')
    calls = []

    def log_again() -> None:
        calls.append(1)
        if len(calls) < 5:
            nested.warning('logged from inside the forward')

    node_logger.on_log = log_again
    logging.getLogger(f'{PACKAGE}.client').warning('outer')
    assert node_logger.lines == [('warn', f'{PACKAGE}.client: outer')]
    assert 'logged from inside the forward' in capsys.readouterr().err


# ---------------------------------------------------------------- a real node on /rosout
class BridgedNode(GimbalDriverNode):
    """A driver node whose package (this test module) is bridged like a driver's."""


@pytest.mark.ros
def test_a_driver_node_forwards_library_lines_to_rosout_under_its_name() -> None:
    with DomainLease() as domain:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        try:
            listener = rclpy.create_node('rosout_listener', context=context)
            received: list[Log] = []
            qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
            listener.create_subscription(Log, '/rosout', received.append, qos)
            node = BridgedNode('bridged_driver', context=context)
            executor = rclpy.executors.SingleThreadedExecutor(context=context)
            executor.add_node(listener)
            try:
                assert node.log_bridge.installed
                module = logging.getLogger(__name__)
                session = logging.getLogger('gimbal_driver_common.session')

                def seen(text: str) -> Log | None:
                    executor.spin_once(timeout_sec=0.05)
                    return next((m for m in received if text in m.msg), None)

                # /rosout matches late: log until the listener has one, then the rest
                wait_for(lambda: (module.info('warm-up') and None) or seen('warm-up'), 20.0,
                         'the warm-up line on /rosout')
                module.warning('resync: skipped 5 bytes')
                session.error('tcp://127.0.0.1:1: link lost')
                warning = wait_for(lambda: seen('resync'), 10.0, 'the warning on /rosout')
                error = wait_for(lambda: seen('link lost'), 10.0, 'the error on /rosout')
                assert warning.level == Log.WARN and warning.name == 'bridged_driver'
                assert warning.msg == f'{__name__}: resync: skipped 5 bytes'
                assert error.level == Log.ERROR and error.name == 'bridged_driver'
                assert error.msg.startswith('gimbal_driver_common.session: ')
                assert len([m for m in received if 'resync' in m.msg]) == 1
            finally:
                executor.shutdown()
                node.destroy_node()
                listener.destroy_node()
            assert not node.log_bridge.installed
            assert node.log_bridge not in logging.getLogger(CORE_LOGGER).handlers
        finally:
            rclpy.shutdown(context=context)

