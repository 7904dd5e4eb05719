"""`scripts/new_driver.py`: a package generated from the reference builds and passes the
conformance suite as it is, under its new names only.

The generated package is built with colcon into a workspace of its own (on top of this
one) and its own ``test/test_conformance.py`` runs against its own simulator there.
"""

from __future__ import annotations

import ast
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / 'scripts' / 'new_driver.py'


def load_new_driver():
    spec = importlib.util.spec_from_file_location('new_driver', SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope='module')
def generated(tmp_path_factory) -> Path:
    dest = tmp_path_factory.mktemp('new_driver') / 'src'
    done = subprocess.run([sys.executable, str(SCRIPT), 'pelco_d', '--dest', str(dest),
                           '--title', 'Pelco-D head', '--port', '4961'],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert '| `pelcod-reader` | `pelco_d` | always |' in done.stdout  # the rows to add
    return dest / 'pelco_d_driver'


def test_the_copy_has_only_the_new_names(generated: Path) -> None:
    names = {str(p.relative_to(generated)) for p in generated.rglob('*') if p.is_file()}
    assert {'pelco_d_driver/node.py', 'pelco_d_driver/sim.py', 'resource/pelco_d_driver',
            'launch/pelco_d_driver.launch.py', 'config/pelco_d_driver_sim.yaml',
            'urdf/pelco_d_driver.urdf', 'test/test_conformance.py',
            'test/test_protocol_vectors.py'} <= names
    for path in generated.rglob('*'):
        if path.is_file():
            text = path.read_text(encoding='utf-8')
            for old in ('virtual_gimbal', 'VirtualGimbal', 'vgimbal', '4950'):
                assert old not in text, f'{path.relative_to(generated)} still says {old!r}'
    setup = (generated / 'setup.py').read_text()
    assert "'pelco_d = pelco_d_driver.registration:SPEC'" in setup
    assert "'pelco_d_sim = pelco_d_driver.sim:main'" in setup
    assert 'class PelcoDNode(' in (generated / 'pelco_d_driver' / 'node.py').read_text()


def test_each_module_to_replace_says_what_and_keeps_its_docstring(generated: Path) -> None:
    for relative in load_new_driver().STUBS:
        path = generated / 'pelco_d_driver' / relative
        tree = ast.parse(path.read_text())
        assert ast.get_docstring(tree), f'{relative} lost its docstring'
        assert '# NEW DRIVER: ' in path.read_text(), relative


def test_names_that_are_no_package_stem_are_refused(tmp_path: Path) -> None:
    module = load_new_driver()
    for bad in ('Pelco', 'pelco-d', '9pelco', 'pelco_driver'):
        with pytest.raises(ValueError, match='package stem'):
            module.generate(bad, tmp_path, 4961, 'x')
    module.generate('pelco', tmp_path, 4961, 'x')
    with pytest.raises(FileExistsError):
        module.generate('pelco', tmp_path, 4961, 'x')


@pytest.mark.ros
@pytest.mark.timeout(3000)  # a colcon build and a whole conformance suite
def test_the_generated_package_builds_and_passes_the_conformance_suite(
        generated: Path) -> None:
    """colcon builds it on top of this workspace; its conformance suite, run in its package
    directory as ``colcon test`` runs it (its own pytest.ini), passes against its own
    install (the suite finds it through the registry's entry point)."""
    if not (ROOT / 'install' / 'setup.bash').is_file():
        pytest.skip('the workspace is not built (make build)')
    workspace = generated.parent.parent
    env = {k: v for k, v in os.environ.items() if not k.startswith('PYTEST')}
    shell = (f'source {ROOT}/scripts/ros_env.sh && cd {workspace} && '
             f'colcon build --symlink-install --base-paths src --cmake-args '
             f'-DPython3_EXECUTABLE=$VIRTUAL_ENV/bin/python '
             f'--event-handlers console_direct- && '
             f'source install/setup.bash && cd src/pelco_d_driver && '
             f'python -m pytest -p no:cacheprovider -q test/test_conformance.py')
    done = subprocess.run(['bash', '-c', shell], capture_output=True, text=True,
                          timeout=3000, env=env, cwd=workspace)
    tail = (done.stdout + done.stderr)[-4000:]
    assert done.returncode == 0, tail
    assert ' passed' in done.stdout and ' failed' not in done.stdout, tail
