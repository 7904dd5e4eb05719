"""The short soak inside `make test`: each driver ~30 s under faults and random traffic.

Runs ``scripts/soak.py <driver> --seconds 30`` as a user would (a process of its own, with
its seeded randomness) and asserts every criterion of the driver's JSON report, naming the
failed ones with their values. `make soak` runs the same code longer (SOAK_S).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parent.parent
SHORT_SOAK_S = 30
SEED = 14


def soaked_drivers() -> list[str]:
    """Every registered driver with an in-process simulator (what `make soak` runs)."""
    try:
        from gimbal_driver_common.registry import drivers
    except ImportError:  # not built: the test skips
        return []
    return [spec.name for spec in drivers() if spec.sim_handle]


@pytest.mark.timeout(600)
@pytest.mark.parametrize('driver', soaked_drivers())
def test_short_soak_meets_every_criterion(driver: str, tmp_path: Path) -> None:
    if not (ROOT / 'install' / 'setup.bash').exists():
        pytest.skip('the workspace is not built (make build)')
    report_file = tmp_path / 'soak.json'
    run = subprocess.run(
        [sys.executable, str(ROOT / 'scripts' / 'soak.py'), driver,
         '--seconds', str(SHORT_SOAK_S), '--seed', str(SEED), '--report', str(report_file)],
        cwd=ROOT, env={k: v for k, v in os.environ.items() if k != 'ROS_DOMAIN_ID'},
        capture_output=True, text=True, timeout=580)
    assert report_file.exists(), f'no report:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}'
    (report,) = json.loads(report_file.read_text(encoding='utf-8'))
    assert 'error' not in report, f'{report["error"]}\n{report.get("traceback")}'
    assert report['seed'] == SEED
    failed = {name: check for name, check in report['criteria'].items() if not check['pass']}
    assert not failed, f'{driver} soak failed {sorted(failed)}:\n' + json.dumps(
        failed, indent=1, default=str) + f'\nnode log: {report["node_log"]}'
    assert report['pass'] and run.returncode == 0
    assert report['faults_injected'] >= len(report['faults_by_kind'])
    assert report['commands_sent'] > 0 and report['calls_sent'] > 0
