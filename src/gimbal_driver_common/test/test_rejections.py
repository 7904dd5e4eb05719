"""CommandRejections: every refused joint_command counted by reason, each reason logged at
most once per period (a 100 Hz stream of refused commands must not flood the log)."""

from __future__ import annotations

import math

import pytest

from gimbal_driver_common.diagnostics import Level
from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout
from gimbal_driver_common.joint_command import CommandError, JointLimits, validate_joint_command
from gimbal_driver_common.rejections import LOG_PERIOD_S, CommandRejections


class RecordingLog:
    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def info(self, msg: str) -> None:
        self.lines.append(('info', msg))

    def warning(self, msg: str) -> None:
        self.lines.append(('warning', msg))

    def error(self, msg: str) -> None:
        self.lines.append(('error', msg))


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def rejection(position: float) -> CommandError:
    try:
        validate_joint_command(['pan'], [position], [], {'pan': JointLimits(-1.0, 1.0, 1.0)})
    except CommandError as exc:
        return exc
    raise AssertionError('not rejected')


def test_a_stream_with_one_reason_logs_once_per_period_and_counts_every_message() -> None:
    log, clock = RecordingLog(), Clock()
    rejections = CommandRejections(log, clock=clock)
    for i in range(301):  # 3 s of a 100 Hz stream, each message with another value
        clock.now += 0.01
        rejections.record(rejection(2.0 + i * 1e-3))
    assert len(log.lines) == 1
    level, line = log.lines[0]
    assert level == 'warning'
    assert line.startswith(
        "joint_command rejected, nothing sent: joint 'pan': position 2.0000 outside")
    assert rejections.counts()['rejected'] == {'pan: position outside the limits': 301}
    clock.now += LOG_PERIOD_S  # the period has passed: the next one is logged, with the count
    rejections.record(rejection(3.0))
    assert len(log.lines) == 2
    assert log.lines[1][1].endswith('(300 more for this reason since the last such line)')


def test_each_distinct_reason_is_logged_on_its_own() -> None:
    log, clock = RecordingLog(), Clock()
    rejections = CommandRejections(log, clock=clock)
    for _ in range(50):
        rejections.record(rejection(2.0))
        rejections.record(rejection(math.inf))
        rejections.record(DeviceRefused('node is not active (lifecycle)',
                                        reason='node not active'))
        rejections.record(DeviceTimeout('MOT_Update: no reply within 0.5 s'), sent=True)
    assert [level for level, _ in log.lines] == ['warning', 'warning', 'warning', 'error']
    assert log.lines[2][1] == ('joint_command refused, nothing sent: node is not active '
                               '(lifecycle)')
    assert log.lines[3][1] == ('joint_command failed on the device: MOT_Update: no reply '
                               'within 0.5 s')
    assert rejections.counts() == {
        'rejected': {'pan: position not finite': 50, 'pan: position outside the limits': 50},
        'refused': {'failed on the device: no answer from the device': 50,
                    'node not active': 50}}


def test_the_diagnostics_part_counts_by_kind_and_reason_at_level_ok() -> None:
    rejections = CommandRejections(RecordingLog(), clock=Clock())
    empty = rejections.status_part()
    assert (empty.part, empty.level, empty.message) == ('joint_command', Level.OK,
                                                        'none rejected or refused')
    assert dict(empty.values) == {'rejected': '0', 'refused': '0'}
    for _ in range(3):
        rejections.record(rejection(2.0))
    rejections.record(DeviceRefused('pan is faulted (over_current)',
                                    reason='the device cannot move the axes'))
    part = rejections.status_part()
    assert part.level == Level.OK and part.message == '3 rejected, 1 refused'
    assert part.values == [('rejected', '3'), ('refused', '1'),
                           ('rejected: pan: position outside the limits', '3'),
                           ('refused: the device cannot move the axes', '1')]


def test_warnings_and_errors_go_through_rclpys_logger() -> None:
    """rclpy remembers each call site's severity and raises if it changes: a refusal (a
    warning) and a failed send (an error) must not share one call site. It did, and the
    ValueError ended the controller's command thread (seen in the Capture soak)."""
    rclpy_logging = pytest.importorskip('rclpy.logging')
    rejections = CommandRejections(rclpy_logging.get_logger('test_rejections'), period=0.0)
    for _ in range(2):
        rejections.record(rejection(2.0))
        rejections.record(DeviceTimeout('MOT_Update: no reply within 0.5 s'), sent=True)
    assert rejections.counts()['refused'] == {
        'failed on the device: no answer from the device': 2}
