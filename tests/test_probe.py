"""gimbal_probe against every registered simulator over its real transport (TCP, pty, slcan
over a pty), and against lines with no device: silent, garbage, an echo, a half-open port.

Every driver with a probe and an in-process simulator handle is found by the whole
registry's probe (the other drivers' attempts run too and must not claim it), and the
simulator's receive log holds no request that changes anything. The parameters file the
probe writes starts the driver node, which reaches active against the same simulator.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from probe_links import link_arguments

from gimbal_driver_common import probe_cli
from gimbal_driver_common.registry import DriverSpec, drivers, resolve
from gimbal_driver_common.sim_handle import SimHandle, make_handle
from gimbal_driver_testing import DomainLease, ManagedProcess, find_executable, ros_env
from gimbal_driver_testing.ros import RosTestClient

PROBED = [spec for spec in drivers() if spec.probe and spec.sim_handle]


def run_probe(argv: list[str]) -> tuple[int, str]:
    out = io.StringIO()
    status = probe_cli.main(argv, out=out)
    return status, out.getvalue()


@pytest.fixture
def simulator(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[SimHandle]:
    handle = make_handle(request.param, tmp_path)
    handle.start()
    try:
        yield handle
    finally:
        handle.stop()


@pytest.mark.parametrize('simulator', PROBED, ids=lambda s: s.name, indirect=True)
def test_the_probe_finds_each_simulator_and_sends_only_reads(simulator: SimHandle,
                                                              tmp_path: Path) -> None:
    spec = simulator.spec
    parameters = simulator.node_parameters()
    output = tmp_path / 'found.yaml'
    status, text = run_probe([*link_arguments(parameters, spec.password), '--output',
                              str(output)])
    assert status == probe_cli.EXIT_FOUND, text
    assert 'Traceback' not in text
    assert f'({spec.name} driver, node {spec.node_name})' in text, text
    changes = [r for r in simulator.requests() if simulator.changing(r)]
    assert not changes, f'the probe sent requests that change the device: {changes}'
    found = yaml.safe_load(output.read_text())['/**']['ros__parameters']
    for key in ('host', 'port', 'serial_port', 'can_channel', 'can_interface'):
        if key in parameters:
            assert found[key] == parameters[key], key
    if spec.password:
        assert spec.password not in text
        assert spec.password not in output.read_text()


@pytest.mark.parametrize('simulator', [s for s in PROBED if s.password], ids=lambda s: s.name,
                         indirect=True)
def test_a_device_with_a_password_is_found_and_the_probe_says_one_is_needed(
        simulator: SimHandle) -> None:
    status, text = run_probe(link_arguments(simulator.node_parameters()))
    assert status == probe_cli.EXIT_FOUND, text
    assert 'a password is needed' in text
    assert simulator.spec.password not in text
    status, text = run_probe(link_arguments(simulator.node_parameters(), 'not-the-password'))
    assert status == probe_cli.EXIT_FOUND, text
    assert 'does not match the device password (it was not sent)' in text
    assert 'not-the-password' not in text and simulator.spec.password not in text
    # the device got nothing but DeviceInfo requests: no login with a wrong password
    assert set(simulator.requests()) == {'GetDeviceInfo'}


def test_a_capture_pedestal_on_a_serial_port(tmp_path: Path) -> None:
    pytest.importorskip('capture_driver')
    from capture_driver.sim import CaptureSimulator, PedestalModel

    link = str(tmp_path / 'capture_tty')
    sim = CaptureSimulator(PedestalModel(), tcp_port=None, pty=True, pty_link=link).start()
    try:
        status, text = run_probe(['--serial', link])
    finally:
        sim.stop()
    assert status == probe_cli.EXIT_FOUND, text
    assert 'Found: Capture Systems pan-tilt pedestal' in text
    assert 'baudrate 115200' in text and 'serial number' in text


def test_a_turret_at_another_node_id_is_found_by_listening(tmp_path: Path) -> None:
    pytest.importorskip('canaero_turret_driver')
    from canaero_turret_driver.sim import SimConfig, SlcanSession, TurretSimulator
    from gimbal_driver_common.sim_server import PtySimServer

    link = str(tmp_path / 'turret_tty')
    turret = TurretSimulator(SimConfig(turret_node_id=7))
    server = PtySimServer(lambda: SlcanSession(turret), link_path=link).start()
    output = tmp_path / 'turret.yaml'
    try:
        status, text = run_probe(['--can', link, '--can-interface', 'slcan', '--can-bitrate',
                                  '500000', '--output', str(output)])
    finally:
        server.stop()
    assert status == probe_cli.EXIT_FOUND, text
    assert 'turret_node_id 7' in text
    found = yaml.safe_load(output.read_text())['/**']['ros__parameters']
    assert (found['turret_node_id'], found['can_bitrate']) == (7, 500000)


class FakeLine:
    """A pseudo-terminal with no device behind it: silent, echoing, sending garbage, or
    hanging up (the far end closes at the first bytes it gets: reads then fail)."""

    def __init__(self, behaviour: str) -> None:
        self.master, self.slave = os.openpty()
        self.path = os.ttyname(self.slave)
        self.behaviour = behaviour
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        import select

        noise = bytes(range(7, 250, 3))
        while not self.stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.01)
            data = os.read(self.master, 4096) if ready else b''
            if self.behaviour == 'hangup' and data:
                os.close(self.master)
                self.master = -1
                return
            if self.behaviour == 'echo' and data:
                os.write(self.master, data)
            elif self.behaviour == 'garbage':
                os.write(self.master, noise)

    def close(self) -> None:
        self.stop.set()
        if self.thread.is_alive():
            self.thread.join(2.0)
        for fd in (self.master, self.slave):
            if fd >= 0:
                os.close(fd)


@pytest.mark.parametrize(('behaviour', 'said'), [
    ('silent', 'silent: no byte came back'),
    ('garbage', 'came back, not a'),
    ('echo', 'the line echoes what is sent'),
    ('hangup', 'the link failed before any answer'),
])
def test_a_serial_line_without_a_device_gives_clear_lines_and_exit_1(behaviour: str,
                                                                     said: str) -> None:
    line = FakeLine(behaviour)
    try:
        status, text = run_probe(['--serial', line.path, '--timeout', '0.5'])
    finally:
        line.close()
    assert status == probe_cli.EXIT_NOTHING, text
    assert 'Traceback' not in text
    assert f'No device answered on serial port {line.path}. Tried:' in text
    assert said in text, text


def test_a_serial_port_that_does_not_exist(tmp_path: Path) -> None:
    status, text = run_probe(['--serial', str(tmp_path / 'ttyNONE')])
    assert status == probe_cli.EXIT_NOTHING
    assert 'cannot open' in text and 'Traceback' not in text


def test_a_can_channel_that_does_not_exist(tmp_path: Path) -> None:
    status, text = run_probe(['--can', str(tmp_path / 'ttyACM9'), '--can-interface', 'slcan'])
    assert status == probe_cli.EXIT_NOTHING
    assert 'cannot open CAN interface slcan:' in text and 'Traceback' not in text


def test_nothing_listening_on_tcp() -> None:
    from gimbal_driver_testing import free_tcp_port

    status, text = run_probe(['--tcp', f'127.0.0.1:{free_tcp_port()}'])
    assert status == probe_cli.EXIT_NOTHING
    assert 'cannot connect' in text and 'Traceback' not in text


def test_a_tcp_peer_that_accepts_and_hangs_up() -> None:
    """A half-open service: the connection is accepted and closed at once, each time."""
    import socket

    listener = socket.create_server(('127.0.0.1', 0))
    stop = threading.Event()

    def hang_up() -> None:
        listener.settimeout(0.05)
        while not stop.is_set():
            try:
                connection, _ = listener.accept()
            except TimeoutError:
                continue
            connection.close()

    thread = threading.Thread(target=hang_up, daemon=True)
    thread.start()
    try:
        status, text = run_probe(['--tcp', f'127.0.0.1:{listener.getsockname()[1]}'])
    finally:
        stop.set()
        thread.join(2.0)
        listener.close()
    assert status == probe_cli.EXIT_NOTHING, text
    assert 'Traceback' not in text
    attempts = [line for line in text.splitlines() if ' on TCP port ' in line and ': no: ' in line]
    assert len(attempts) == 3, text
    assert all('the link failed before any answer' in line for line in attempts), text
    assert 'silent' not in text


#: the module constant of each TCP driver's probe that holds its documented port
DOCUMENTED_PORT = {'virtual_gimbal': 'DEFAULT_PORT', 'capture': 'TCP_PORT',
                   'kessler_kos': 'DEFAULT_TCP_PORT'}


@pytest.mark.parametrize('simulator', [s for s in PROBED if s.name in DOCUMENTED_PORT],
                         ids=lambda s: s.name, indirect=True)
def test_a_host_without_a_port_is_tried_on_each_documented_port(
        simulator: SimHandle, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each device's documented port stands in for a free one here (the real ports may be
    in use on a shared machine): the one of the simulator's device is its port."""
    from gimbal_driver_testing import free_tcp_port

    for spec in PROBED:
        if spec.name in DOCUMENTED_PORT:
            module = sys.modules[resolve(spec.probe).__module__]
            port = simulator.port if spec is simulator.spec else free_tcp_port()
            monkeypatch.setattr(module, DOCUMENTED_PORT[spec.name], port)
    status, text = run_probe(['--tcp', '127.0.0.1', *(
        ['--password', simulator.spec.password] if simulator.spec.password else [])])
    assert status == probe_cli.EXIT_FOUND, text
    assert f'({simulator.spec.name} driver' in text
    assert text.count('ANSWERED') == 1 and text.count(' on TCP port ') == len(DOCUMENTED_PORT)


def by_name(name: str) -> DriverSpec:
    return next(spec for spec in PROBED if spec.name == name)


@pytest.mark.parametrize('simulator', [by_name('virtual_gimbal')], ids=lambda s: s.name,
                         indirect=True)
def test_the_installed_executable(simulator: SimHandle, tmp_path: Path) -> None:
    output = tmp_path / 'params.yaml'
    result = subprocess.run(
        [find_executable('gimbal_driver_common', 'gimbal_probe'), '--tcp',
         f'127.0.0.1:{simulator.port}', '--output', str(output)],
        capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'Found: virtual gimbal' in result.stdout
    assert yaml.safe_load(output.read_text()) == {'/**': {
        'ros__parameters': {'host': '127.0.0.1', 'port': simulator.port}}}


@pytest.mark.parametrize('simulator', PROBED, ids=lambda s: s.name, indirect=True)
def test_the_written_parameters_start_the_driver(simulator: SimHandle, tmp_path: Path) -> None:
    """The probe's file as the node's params_file: the node reaches active on its own."""
    spec = simulator.spec
    parameters = simulator.node_parameters()
    output = tmp_path / 'probed.yaml'
    status, text = run_probe([*link_arguments(parameters, spec.password), '--output',
                              str(output)])
    assert status == probe_cli.EXIT_FOUND, text
    arguments = ['--ros-args', '--params-file', str(output)]
    if 'password_file' in parameters:  # the probe never writes a password: the user adds it
        arguments += ['-p', f'password_file:={parameters["password_file"]}']
    with DomainLease() as domain:
        node = ManagedProcess([find_executable(spec.package, spec.node_executable),
                               *arguments], ros_env(domain), name=spec.node_executable)
        try:
            with RosTestClient(domain, 'probe_check') as ros:
                ros.wait_for_lifecycle_state(spec.node_name, 'active', timeout=60)
        finally:
            node.stop()
