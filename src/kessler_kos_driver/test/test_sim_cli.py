"""The kessler_kos_sim executable: argument checks, listening line, control port."""

import os
import re
import signal
import subprocess
import sys

from kessler_kos_driver.client import KosClient
from kessler_kos_driver.sim import control


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
        line = proc.stdout.readline()
        match = re.search(r'127\.0\.0\.1:(\d+) control 127\.0\.0\.1:(\d+)', line)
        assert match, line
        port, control_port = int(match[1]), int(match[2])
        client = KosClient('127.0.0.1', port, password='pw', poll_period=0)
        client.connect()
        assert sorted(client.motors) == [1, 2, 3, 4] and client.motors[4].is_fiz
        client.close()
        assert control(control_port, 'status').startswith('ok phase=idle')
        assert control(control_port, 'bogus').startswith('error unknown command')
        assert control(control_port, 'offline 99').startswith('error')
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=10)
    assert proc.returncode == 0
