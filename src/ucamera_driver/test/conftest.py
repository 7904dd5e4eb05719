"""Shared fixtures: a fast simulator on a real pseudo-terminal and a client on it."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import pytest

from ucamera_driver.protocol import GimbalType
from ucamera_driver.sim import SimConfig, UCameraSim


def fast_config(**overrides) -> SimConfig:
    values = dict(
        telemetry_rate=50, max_rate=math.radians(180.0), acceleration=math.radians(1800.0),
        init_time=0.1, autoalign_time=0.3, ffc_time=0.2, save_pause=0.6,
        gimbal_type=GimbalType.IR,
    )
    values.update(overrides)
    return SimConfig(**values)


@pytest.fixture
def make_config() -> Callable[..., SimConfig]:
    """Factory of fast simulator configurations (tests import nothing from conftest)."""
    return fast_config


@pytest.fixture
def sim() -> Iterator[UCameraSim]:
    simulator = UCameraSim(fast_config()).start()
    yield simulator
    simulator.stop()
