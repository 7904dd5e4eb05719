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
    config = ClientConfig(interface="virtual", channel=channel_name, service_timeout=0.5)
    turret = TurretClient(config)
    turret.open()
    yield turret
    turret.close()


class FlakyBus(can.BusABC):
    """A virtual bus whose receive fails while `script` holds faults: "raise" (the adapter
    vanished) or "busoff" (an error frame with the bus-off bit); a test may add more later."""

    def __init__(self, channel, script):
        self._inner = can.Bus(interface="virtual", channel=channel)
        self._script = script
        super().__init__(channel=channel)

    def _recv_internal(self, timeout):
        if self._script:
            action = self._script.pop(0)
            if action == "raise":
                raise can.CanOperationError("adapter unplugged")
            if action == "busoff":
                return can.Message(is_error_frame=True, arbitration_id=0x40), False
        return self._inner._recv_internal(timeout)

    def send(self, msg, timeout=None):
        self._inner.send(msg, timeout)

    def shutdown(self):
        self._inner.shutdown()
        super().shutdown()


@pytest.fixture
def flaky_bus():
    """The FlakyBus class, for a client's bus_factory."""
    return FlakyBus


@pytest.fixture
def spy_bus(channel_name):
    """A third bus on the same virtual channel, to watch or inject raw frames."""
    bus = can.Bus(interface="virtual", channel=channel_name)
    yield bus
    bus.shutdown()


def _controller_config(**overrides):
    """The turret's default joints and limits as a ControllerConfig (fast reconnects)."""
    import math

    from gimbal_driver_common.controller import ControllerConfig
    from gimbal_driver_common.joint_command import limits_from_parameters

    joints = ["yaw", "pitch"]
    limits = limits_from_parameters(joints, [-math.pi, math.radians(-30.0)],
                                    [math.pi, math.radians(60.0)],
                                    [math.radians(60.0), math.radians(40.0)])
    values = dict(joint_names=joints, limits=limits, publish_rate=50.0, command_timeout=0.4,
                  reconnect_period=0.2, goal_tolerance=0.011, move_timeout=30.0)
    values.update(overrides)
    return ControllerConfig(**values)


@pytest.fixture(scope="session")
def controller_config():
    """`_controller_config`: ControllerConfig for the turret's joints, with overrides."""
    return _controller_config


@contextlib.contextmanager
def _supervised(client, settings=None, **config):
    """`client` as a `TurretDevice` run by gimbal_driver_common's controller (the link
    supervisor the node uses), open and active; yields the controller."""
    import logging

    from canaero_turret_driver.device import TurretDevice, TurretSettings
    from gimbal_driver_common.controller import GimbalController

    controller_config = _controller_config(**config)
    log = logging.getLogger("canaero_turret_driver.test")
    device = TurretDevice(client, settings or TurretSettings(),
                          lambda: controller_config.publish_rate, log)
    controller = GimbalController(device, controller_config, log)
    controller.open()
    controller.activate()
    try:
        yield controller
    finally:
        controller.shutdown()


@pytest.fixture(scope="session")
def supervised():
    """The `_supervised` context manager: a client under the controller's supervisor."""
    return _supervised


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
    from gimbal_driver_testing import DomainLease, ManagedProcess, ros_arguments, wait_for
    from gimbal_driver_testing.ros import RosTestClient

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
                                      domain, ros_arguments(params))
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
