"""Nothing test-only at run time: every registered simulator, node and the probe start and
work with pytest, hypothesis, geographiclib and the test support package blocked from
import, as on a robot that installed the drivers without their test dependencies. And a
node imports at start-up nothing a feature needs only when used (``AT_FIRST_USE``: pymap3d
at the first geographic aim; lxml and urdf_parser_py never, the URDF is read with the
standard library), each of which costs every node memory (bench/README.md, "What a node
imports").

Each child process gets a ``sitecustomize`` module on its ``PYTHONPATH`` (site imports it at
start-up) that puts a finder first on ``sys.meta_path``: it raises ImportError for the
blocked packages and logs that it was installed and each import it refused, so the test
knows the block was in force in every process it started.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from probe_links import link_arguments

from gimbal_driver_common import probe_cli
from gimbal_driver_common.registry import DriverSpec, drivers, parameter_arguments
from gimbal_driver_common.sim_control import parse_ready_line
from gimbal_driver_testing import (
    DomainLease,
    ManagedProcess,
    find_executable,
    free_tcp_port,
    wait_for,
)
from gimbal_driver_testing.ros import RosTestClient

pytestmark = pytest.mark.ros

#: what a robot does not install: the test libraries and the test support
BLOCKED = ('pytest', '_pytest', 'hypothesis', 'geographiclib', 'gimbal_driver_testing')
#: imported by a node only when a feature is used, never at start-up (logged, not blocked)
AT_FIRST_USE = ('pymap3d', 'dateutil', 'lxml', 'urdf_parser_py')

SITECUSTOMIZE = textwrap.dedent('''
    """Blocks the test-only packages from import (tests/test_runtime_without_test_tools.py)."""
    import os
    import sys

    BLOCKED = {blocked!r}
    AT_FIRST_USE = {at_first_use!r}
    LOG = os.environ['GIMBAL_BLOCKED_IMPORTS_LOG']


    def note(text):
        with open(LOG, 'a', encoding='utf-8') as stream:
            stream.write(f'{{os.getpid()}} {{text}}\\n')


    class BlockTestTools:
        def find_spec(self, name, path=None, target=None):
            if name.split('.')[0] in BLOCKED:
                note(f'refused {{name}}')
                raise ImportError(f'{{name}} is blocked: a test-only package')
            if name in AT_FIRST_USE:
                note(f'imported {{name}}')
            return None


    sys.meta_path.insert(0, BlockTestTools())
    note('installed ' + ' '.join(sys.argv[:1]))
''').format(blocked=BLOCKED, at_first_use=AT_FIRST_USE)


@pytest.fixture
def blocked_env(tmp_path: Path) -> dict[str, str]:
    """Environment additions for a child process with the test tools blocked."""
    site = tmp_path / 'blocked_site'
    site.mkdir()
    (site / 'sitecustomize.py').write_text(SITECUSTOMIZE, encoding='utf-8')
    path = os.pathsep.join(p for p in (str(site), os.environ.get('PYTHONPATH', '')) if p)
    return {'PYTHONPATH': path, 'GIMBAL_BLOCKED_IMPORTS_LOG': str(tmp_path / 'blocked.log')}


def log_of(env: dict[str, str]) -> str:
    log = Path(env['GIMBAL_BLOCKED_IMPORTS_LOG'])
    return log.read_text(encoding='utf-8') if log.exists() else ''


def installed_in(env: dict[str, str], process: ManagedProcess | subprocess.Popen) -> bool:
    pid = process.process.pid if isinstance(process, ManagedProcess) else process.pid
    return f'{pid} installed' in log_of(env)


def test_the_block_works(blocked_env: dict[str, str]) -> None:
    """The check is not vacuous: a child with the block cannot import any blocked package,
    and can import the runtime."""
    env = {**os.environ, **blocked_env}
    for name in BLOCKED:
        result = subprocess.run([sys.executable, '-c', f'import {name}'], env=env,
                                capture_output=True, text=True, timeout=60)
        assert result.returncode != 0 and f'{name} is blocked' in result.stderr, name
    result = subprocess.run([sys.executable, '-c', 'import gimbal_driver_common.registry'],
                            env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert log_of(blocked_env).count('installed') == len(BLOCKED) + 1
    result = subprocess.run([sys.executable, '-c', 'import pymap3d, lxml.etree'], env=env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    noted = [line.split(' ', 1)[1] for line in log_of(blocked_env).splitlines()
             if ' imported ' in line]
    assert {'imported pymap3d', 'imported lxml'} <= set(noted), noted


@pytest.mark.parametrize('spec', drivers(), ids=lambda spec: spec.name)
def test_simulator_probe_and_node_start_without_test_tools(
        spec: DriverSpec, blocked_env: dict[str, str], tmp_path: Path) -> None:
    """The simulator prints its ready line, gimbal_probe finds the device (its registered
    probe, the other drivers' attempts too) and the node reaches active against it."""
    port = free_tcp_port()
    workdir = tmp_path / 'work'
    workdir.mkdir()
    with DomainLease() as domain:
        sim = ManagedProcess.ros(spec.package, spec.sim_executable, domain,
                                 spec.sim_argv(workdir, port), extra_env=blocked_env)
        node = None
        try:
            wait_for(lambda: parse_ready_line(sim.output()) or not sim.running, 60,
                     f'{spec.sim_executable} to be ready')
            assert sim.running, sim.output()[-2000:]
            assert installed_in(blocked_env, sim)
            parameters = spec.parameters(workdir, port)
            if spec.probe:
                probe = subprocess.run(
                    [find_executable('gimbal_driver_common', 'gimbal_probe'),
                     *link_arguments(parameters, spec.password)],
                    env={**os.environ, **blocked_env}, capture_output=True, text=True,
                    timeout=120)
                assert probe.returncode == probe_cli.EXIT_FOUND, probe.stdout + probe.stderr
                assert f'({spec.name} driver, node {spec.node_name})' in probe.stdout
                assert any(line.endswith(' installed ' + probe.args[0])
                           for line in log_of(blocked_env).splitlines()), log_of(blocked_env)
            node = ManagedProcess.ros(spec.package, spec.node_executable, domain,
                                      ['--ros-args', *parameter_arguments(parameters)],
                                      extra_env=blocked_env)
            with RosTestClient(domain, 'no_test_tools_check') as ros:
                ros.wait_for_lifecycle_state(spec.node_name, 'active', timeout=60)
            assert node.running, node.output()[-3000:]
            assert installed_in(blocked_env, node)
            assert 'Traceback' not in node.output(), node.output()[-3000:]
            pid = node.process.pid
            assert [line for line in log_of(blocked_env).splitlines()
                    if line.startswith(f'{pid} imported ')] == [], 'imported at start-up'
        finally:
            if node is not None:
                node.stop()
            sim.stop()

