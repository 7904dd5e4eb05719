"""Shared pytest fixtures of the capture_driver tests."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import pytest

from gimbal_driver_testing import free_tcp_port

PKG = 'capture_driver'


@contextlib.contextmanager
def _capture_rig(sim_arguments: Sequence[str] = (), node_parameters: Sequence[str] = (),
                 **options: Any) -> Iterator[tuple[Any, int]]:
    """capture_sim over TCP and capture_driver_node connected to it, as processes
    (``driver_rig``); yields the rig and the simulator's control port."""
    from gimbal_driver_testing.ros import driver_rig  # rclpy: only for node tests

    port, control_port = free_tcp_port(), free_tcp_port()
    with driver_rig(PKG, 'capture_sim',
                    ['--port', str(port), '--control-port', str(control_port), *sim_arguments],
                    '{"ready": "capture_sim"', 'capture_driver_node',
                    ['host:=127.0.0.1', f'port:={port}', *node_parameters],
                    **options) as started:
        yield started, control_port


@pytest.fixture(scope='session')
def capture_rig() -> Callable[..., contextlib.AbstractContextManager[tuple[Any, int]]]:
    """``with capture_rig(sim_arguments, node_parameters, record=...) as (rig, control_port)``."""
    return _capture_rig
