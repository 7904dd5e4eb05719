"""Shared fixtures: the simulator and a client on an in-process python-can virtual bus."""

import itertools
import os

import can
import pytest

from canaero_turret_driver.client import ClientConfig, TurretClient
from canaero_turret_driver.sim import BusSimRunner, SimConfig, TurretSimulator

_channels = itertools.count()


@pytest.fixture
def channel_name():
    return f"canaero-test-{os.getpid()}-{next(_channels)}"


@pytest.fixture
def simulator(channel_name):
    sim = TurretSimulator(SimConfig())
    bus = can.Bus(interface="virtual", channel=channel_name)
    runner = BusSimRunner(sim, bus).start()
    yield sim
    runner.stop()
    bus.shutdown()


@pytest.fixture
def client(simulator, channel_name):
    config = ClientConfig(interface="virtual", channel=channel_name, service_timeout=0.5,
                          reconnect_period=0.1)
    turret = TurretClient(config)
    turret.open()
    yield turret
    turret.close()


@pytest.fixture
def spy_bus(channel_name):
    """A third bus on the same virtual channel, to watch or inject raw frames."""
    bus = can.Bus(interface="virtual", channel=channel_name)
    yield bus
    bus.shutdown()
