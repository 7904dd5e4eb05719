
"""Client against `canaero_turret_sim` in another process, over slcan on a pseudo-terminal.

This is the real cross-process transport of this machine (no SocketCAN here): the
simulator speaks slcan ASCII on the pty master, the client uses python-can's `slcan`
interface on the pty slave, and faults are injected through the simulator's control
port on 127.0.0.1.
"""

import contextlib
import json
import math
import os
import pathlib
import sys

import pytest

import canaero_turret_driver
import gimbal_driver_common
from canaero_turret_driver.client import ClientConfig, ServiceError, TurretClient
from canaero_turret_driver.readings import si
from canaero_turret_driver.sim import ControlClient
from gimbal_driver_common.sim_control import parse_ready_line
from gimbal_driver_testing import ManagedProcess, wait_for


def _python_path() -> str:
    paths = [str(pathlib.Path(module.__file__).resolve().parent.parent)
             for module in (canaero_turret_driver, gimbal_driver_common)]
    return os.pathsep.join([*paths, os.environ.get("PYTHONPATH", "")])


@contextlib.contextmanager
def running_sim(tmp_path: pathlib.Path, *arguments: str):
    """`canaero_turret_sim` in another process; yields (endpoint, control client)."""
    ready = tmp_path / "ready.json"
    process = ManagedProcess(
        [sys.executable, "-m", "canaero_turret_driver.sim", *arguments,
         "--ready-file", str(ready)],
        dict(os.environ, PYTHONPATH=_python_path()), name="canaero_turret_sim")
    try:
        assert wait_for(ready.exists, timeout=20.0), "simulator did not start"
        endpoint = json.loads(ready.read_text())
        # the ready file holds the one JSON ready line the simulator prints
        assert wait_for(lambda: parse_ready_line(process.output(), "canaero_turret_sim")
                        == endpoint, timeout=20.0)
        control = ControlClient(endpoint["control_port"])
        yield endpoint, control
        control.close()
    finally:
        process.stop(timeout=5.0)


@pytest.fixture
def sim_process(tmp_path):
    with running_sim(tmp_path, "--link", str(tmp_path / "tty")) as sim:
        yield sim


@pytest.fixture
def remote_client(sim_process):
    endpoint, _ = sim_process
    config = ClientConfig(interface="slcan", channel=endpoint["channel"],
                          bus_options={"sleep_after_open": 0}, service_timeout=0.5,
                          node_timeout=0.5, stale_timeout=0.5)
    client = TurretClient(config)
    client.open()
    yield client
    client.close()


def test_identify_move_and_data_across_processes(sim_process, remote_client):
    _, control = sim_process
    assert remote_client.services.identify().software_revision == 7
    assert wait_for(lambda: remote_client.latest("yaw_position") is not None)
    remote_client.move_to("yaw", math.degrees(0.35))
    assert wait_for(lambda: abs(si(remote_client.latest("yaw_position")) - 0.35) < 1e-3)
    # the broadcast is within 1e-3 rad while the axis still creeps in: wait for it to arrive
    assert wait_for(lambda: abs(control.state()["axes"]["yaw"]["position"] - 20.0535) < 0.01)


def test_silence_and_recovery_across_processes(sim_process, remote_client):
    _, control = sim_process
    assert wait_for(lambda: not remote_client.node_silent())
    assert control.command("node_silence turret") == "ok"
    assert wait_for(lambda: remote_client.node_silent())
    with pytest.raises(ServiceError):
        remote_client.services.identify()
    assert control.command("node_silence all off") == "ok"
    assert wait_for(lambda: not remote_client.node_silent()
                    and not remote_client.is_stale("yaw_position"))
    assert control.command("silence on") == "ok"  # the shared verb: every node quiet
    assert wait_for(lambda: remote_client.node_silent()
                    and remote_client.is_stale("yaw_position"))
    assert control.command("silence off") == "ok"
    assert wait_for(lambda: not remote_client.node_silent()
                    and not remote_client.is_stale("yaw_position"))


def test_lost_frames_garbage_and_eed_across_processes(sim_process, remote_client):
    _, control = sim_process
    assert wait_for(lambda: remote_client.latest("yaw_position") is not None)
    assert control.command("lose yaw_position 4") == "ok"
    assert wait_for(lambda: remote_client.sequences.stats((1, 1303)).lost >= 4)
    assert control.command("garbage hex 74315a0d78780d00ff") == "ok 9 bytes"
    assert wait_for(lambda: remote_client.counters.malformed >= 1)
    code = remote_client.latest("yaw_position").message_code
    assert wait_for(lambda: remote_client.latest("yaw_position").message_code != code)
    before = remote_client.counters.malformed
    assert control.command("malformed 3") == "ok"
    assert wait_for(lambda: remote_client.counters.malformed >= before + 3)
    assert control.command("eed 0x42 1 2") == "ok"
    assert wait_for(lambda: any(e.error_code == 0x42 for e in remote_client.events))
    code = remote_client.latest("yaw_position").message_code
    assert wait_for(lambda: remote_client.latest("yaw_position").message_code != code)
    assert control.command("bogus").startswith("error")


def _record_links(client: TurretClient) -> list[bool]:
    """Every link change of `client` (up True, down False), keeping its own callback."""
    links: list[bool] = []
    chained = client.on_link

    def record(up: bool, why: str) -> None:
        links.append(up)
        if chained is not None:
            chained(up, why)

    client.on_link = record
    return links


def _reconnected(controller, links: list[bool]) -> bool:
    """The link went down and came up again, and the controller is connected."""
    return False in links and True in links[links.index(False):] and controller.connected


def test_link_drop_is_reopened_by_the_supervisor(sim_process, remote_client, supervised):
    """The client has no reconnect loop: the controller (as in the node) reopens it."""
    _, control = sim_process
    with supervised(remote_client) as controller:
        links = _record_links(remote_client)
        assert wait_for(lambda: remote_client.latest("yaw_position") is not None)
        assert control.command("drop 0.5") == "ok"
        assert wait_for(lambda: False in links)
        assert wait_for(lambda: _reconnected(controller, links), timeout=30.0)
        assert wait_for(lambda: not remote_client.is_stale("yaw_position"), timeout=10.0)
        assert remote_client.counters.reconnects >= 1
        assert controller.reconnects >= 1
        assert remote_client.services.identify().hardware_revision == 2


@pytest.fixture
def socketcand_sim(tmp_path):
    with running_sim(tmp_path, "--transport", "socketcand") as sim:
        yield sim


def _socketcand_client(endpoint) -> TurretClient:
    config = ClientConfig(interface="socketcand", channel=endpoint["channel"],
                          bus_options={"host": endpoint["host"], "port": endpoint["port"]},
                          service_timeout=0.5, node_timeout=0.5, stale_timeout=0.5,
                          reopen_after_silence=1.0)
    client = TurretClient(config)
    client.open()
    return client


def test_socketcand_bridge_is_a_shared_bus(socketcand_sim, supervised):
    endpoint, control = socketcand_sim
    assert endpoint["host"] == "127.0.0.1"
    first, second = _socketcand_client(endpoint), _socketcand_client(endpoint)
    try:
        with supervised(first) as controller:
            assert first.services.identify().software_revision == 7
            first.move_to("pitch", math.degrees(0.3))
            assert wait_for(lambda: second.latest("pitch_position") is not None
                            and abs(si(second.latest("pitch_position")) - 0.3) < 1e-3)
            assert control.command("node_silence turret") == "ok"
            assert wait_for(lambda: second.node_silent())
            assert control.command("node_silence all off") == "ok"
            assert wait_for(lambda: not second.node_silent())
            assert wait_for(lambda: controller.connected, timeout=30.0)  # after the silence
            links = _record_links(first)
            assert control.command("drop 0.3") == "ok"
            assert wait_for(lambda: False in links)
            assert wait_for(lambda: _reconnected(controller, links), timeout=30.0)
            assert wait_for(lambda: not first.is_stale("yaw_position"), timeout=10.0)
            assert first.services.identify().hardware_revision == 2
    finally:
        first.close()
        second.close()
