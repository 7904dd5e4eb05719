"""The kessler_kos_sim executable: argument checks, ready line, the shared control verbs
acting on the client's TCP link."""

import os
import signal
import subprocess
import sys
import time

import pytest

from gimbal_driver_common.sim_control import ControlClient, read_ready_line
from kessler_kos_driver.client import DeviceTimeout, KosClient
from kessler_kos_driver.protocol import ErrorCode


def run_sim(*args):
    env = dict(os.environ)
    return subprocess.Popen(
        [sys.executable, '-m', 'kessler_kos_driver.sim', *args], stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, env=env)


def test_bad_arguments_exit_with_a_message():
    proc = run_sim('--motors', 'slider,turbo')
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 2 and '--motors' in err


def test_cli_serves_and_obeys_control_commands():
    proc = run_sim('--port', '0', '--control-port', '0', '--discovery-port', '0',
                   '--password', 'pw', '--motors', 'slider,pan,tilt,focus', '--precalibrated',
                   '--time-scale', '10')
    try:
        ready = read_ready_line(proc.stdout, 'kessler_kos_sim')
        assert ready['motors'] == ['slider', 'pan', 'tilt', 'focus']
        client = KosClient('127.0.0.1', ready['port'], password='pw', poll_period=0)
        client.connect()
        assert sorted(client.motors) == [1, 2, 3, 4] and client.motors[4].is_fiz
        with ControlClient(ready['control_port']) as control:
            state = control.state()
            assert state['phase'] == 'idle' and state['axes']['focus']['address'] == 4
            assert control.command('bogus').startswith('error bogus: unknown verb')
            assert control.command('offline 99').startswith('error')
            assert control.command('nack on').startswith('error nack: not applicable')
            # the shared verbs act on the TCP link the client uses
            assert control.command('fault axis 2') == 'ok'
            assert client.wait_for(lambda: any(
                e.code == ErrorCode.AXIS_FAULT and e.motor_address == 2
                for e in client.errors), 10)
            assert control.command('garbage hex 00ff04ffff1234') == 'ok 7 bytes'
            assert client.wait_for(lambda: client.malformed_frames > 0, 10)
            assert control.command('silence on') == 'ok'
            with pytest.raises(DeviceTimeout):
                client.refresh_motors()
            assert control.command('silence off') == 'ok'
            assert control.command('drop 0') == 'ok'
            deadline = time.monotonic() + 10
            while client.connected and time.monotonic() < deadline:
                time.sleep(0.05)
            assert not client.connected
        client.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=10)
    assert proc.returncode == 0
