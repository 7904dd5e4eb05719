"""The test helpers' port choice: outside the kernel's ephemeral range, and bindable."""

from __future__ import annotations

import socket

from gimbal_driver_testing import _ephemeral_port_floor, free_tcp_port


def test_free_tcp_port_is_below_the_ephemeral_range_and_bindable() -> None:
    floor = _ephemeral_port_floor()
    ports = {free_tcp_port() for _ in range(20)}
    assert len(ports) > 1  # random, not one fixed port every test would share
    for port in ports:
        assert 10000 <= port < floor
        with socket.socket() as sock:
            sock.bind(('127.0.0.1', port))


def test_command_counts_reads_every_count_of_the_part_the_node_builds() -> None:
    """The rig's reader of the ``joint_command`` part takes the part the node publishes,
    delivery gaps (a count and seconds) included."""
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    from gimbal_driver_common.command_stream import GAPS_KEY, CommandStream
    from gimbal_driver_common.errors import DeviceRefused
    from gimbal_driver_common.rejections import CommandRejections
    from gimbal_driver_testing.conformance_rig import command_counts

    class Log:
        def info(self, msg: str) -> None: ...
        def warning(self, msg: str) -> None: ...
        def error(self, msg: str) -> None: ...

    now = [0.0]
    stream = CommandStream(Log(), lambda: 0.5, clock=lambda: now[0])
    stream.took(0, 1)
    now[0] = 0.7
    stream.took(10_000_000, 3)  # 0.7 s after, published 10 ms after: a delivery gap
    rejections = CommandRejections(Log())
    rejections.record(DeviceRefused('off', reason='axis off'))
    part = rejections.status_part(stream.values())
    status = DiagnosticStatus(values=[KeyValue(key=k, value=v) for k, v in part.values])
    assert command_counts(status) == {'rejected': 0, 'refused': 1, 'refused: axis off': 1,
                                      GAPS_KEY: 1}
