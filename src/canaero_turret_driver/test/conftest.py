"""Shared fixtures: the simulator and a client on an in-process python-can virtual bus, and
the simulator + node processes of the ROS tests."""

import contextlib
import itertools
import json
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


@pytest.fixture(scope="session")
def sim_and_node():
    """The `_sim_and_node` context manager, for module- and function-scoped rigs."""
    return _sim_and_node


@contextlib.contextmanager
def _sim_and_node(tmp_path, node_params, sim_args=()):
    """`canaero_turret_sim` and the node as processes in a leased ROS domain.

    `node_params(tty)` gives the node's `name:=value` parameters for the simulator's pty.
    Yields (RosTestClient, simulator ControlClient, node ManagedProcess); ROS is imported
    here so that the codec and client tests run without the built workspace.
    """
    from canaero_turret_driver.sim import ControlClient
    from gimbal_driver_common.ros.testing import RosTestClient
    from gimbal_driver_common.testing import DomainLease, ManagedProcess, wait_for

    tty, ready = tmp_path / "tty", tmp_path / "ready.json"
    with DomainLease() as domain:
        sim = ManagedProcess.ros("canaero_turret_driver", "canaero_turret_sim", domain,
                                 ["--link", str(tty), "--ready-file", str(ready), *sim_args])
        node = ros = control = None
        try:
            wait_for(ready.exists, 20, "the simulator to start")
            control = ControlClient(json.loads(ready.read_text())["control_port"])
            params = node_params(str(tty))
            node = ManagedProcess.ros("canaero_turret_driver", "canaero_turret_driver_node",
                                      domain, ["--ros-args", *[x for p in params
                                                               for x in ("-p", p)]])
            ros = RosTestClient(domain)
            yield ros, control, node
        finally:
            if ros is not None:
                ros.close()
            if node is not None:
                node.stop()
            if control is not None:
                control.close()
            sim.stop()
