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
