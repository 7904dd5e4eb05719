"""Tracking: a 100 Hz interpolated trajectory through ros2_control's topic interface.

What a user's ros2_control stack does with a driver: the controller manager at
100 Hz, a joint_trajectory_controller running a rest-to-rest trajectory (its quintic
spline), joint_state_topic_hardware_interface writing every cycle to the node's
joint_command. ``trajectory_publisher.py`` (its own process) plays that with the package's
``<ros2_control>`` example; the node runs in the example's namespace, the simulator in this
process. Each run moves one joint by ``AMPLITUDE`` in ``DURATION_S`` (the issue's 0.5 rad
in 2 s), alternating direction, and holds the goal for ``SETTLE_S``.

The tracking error is, for every joint_states sample in a run (stamped when the device data
reached the node), ``|position - trajectory(stamp)|``: p50, p99, max over all runs, and the
worst run. Beside it, what the simulator's own motion limits allow: a device that gets a
new target every control period ``T`` and accelerates at ``a`` follows a trajectory whose
peak speed is ``v`` at most ``v * T`` (the target is up to one period old) plus ``v² / 2a``
(the distance it needs behind its target to run at ``v``) behind. ``a`` and the speed limit
of a position move are read from the simulator's axis after the runs
(``SimHandle.axis_limits``: what the driver set up, or the device's own profile).
"""

from __future__ import annotations

import json
import math
import statistics
import sys
import tempfile
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from driver_bench import add_note, start_node
from harness import ROOT, freeze_heap

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_handle import make_handle
from gimbal_driver_testing import ManagedProcess, ros_env, wait_for
from gimbal_driver_testing.topic_system import UPDATE_RATE_HZ, rest_to_rest_peak_speed

AMPLITUDE = 0.5       # rad (m for a linear joint)
DURATION_S = 2.0
SETTLE_S = 0.5
RUNS = 6


def tracking_figures(spec: DriverSpec, domain: int, runs: int = RUNS) -> dict:
    """The trajectory runs against one driver; see the module docstring."""
    joint = spec.bench.stream_joint or spec.joints[0]
    block = Path(get_package_share_directory(spec.package), 'config',
                 f'{spec.package}.ros2_control.xacro')
    with tempfile.TemporaryDirectory(prefix=f'bench-tracking-{spec.name}-') as workdir:
        handle = make_handle(spec, Path(workdir))
        handle.start()
        try:
            parameters = {**handle.node_parameters(), 'publish_rate': spec.bench.publish_rate,
                          'presets_file': str(Path(workdir, 'presets.yaml'))}
            # in the example's namespace: the remapping that keeps joint_states off
            # /joint_states, where the example's block reads them
            node = start_node(domain, spec.package, parameters,
                              executable=spec.node_executable, namespace=spec.namespace)
            try:
                recorded = play(domain, block, joint, runs, Path(workdir))
                speed_limit, acceleration = handle.axis_limits(joint)
            finally:
                code = node.stop(timeout=5.0)
        finally:
            handle.stop()
    results = figures(recorded, joint, speed_limit, acceleration)
    if code not in (0, -2, 130):
        add_note(results, f'node exited with code {code}')
    return results


def play(domain: int, block: Path, joint: str, runs: int, workdir: Path) -> dict:
    settings = workdir / 'trajectory.json'
    settings.write_text(json.dumps({'block': str(block), 'joint': joint,
                                    'amplitude': AMPLITUDE, 'duration': DURATION_S,
                                    'settle_s': SETTLE_S, 'runs': runs}))
    output = workdir / 'recorded.json'
    publisher = ManagedProcess([sys.executable, str(ROOT / 'bench' / 'trajectory_publisher.py'),
                                str(settings), str(output)], ros_env(domain),
                               name='trajectory_publisher')
    try:
        wait_for(lambda: output.exists() or not publisher.running,
                 90.0 + runs * (DURATION_S + SETTLE_S), 'the trajectory runs')
        if not output.exists():
            raise RuntimeError(f'trajectory publisher failed:\n{publisher.output()[-2000:]}')
        return json.loads(output.read_text())
    finally:
        publisher.stop(timeout=5.0)


def figures(recorded: dict, joint: str, speed_limit: float, acceleration: float) -> dict:
    """Errors of every run against its trajectory, and the bound the device's limits give."""
    errors: list[float] = []
    worst = {'error_rad': -1.0}
    for index, run in enumerate(recorded['runs']):
        t0, start, goal = run['t0'], run['start'], run['goal']
        duration = run['duration']
        for stamp, position in recorded['states']:
            t = stamp - t0
            if not 0.0 <= t <= duration + SETTLE_S:
                continue
            s = min(t / duration, 1.0)
            desired = start + (goal - start) * s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s)
            error = abs(position - desired)
            errors.append(error)
            if error > worst['error_rad']:
                worst = {'error_rad': round(error, 4), 'run': index, 't_s': round(t, 3)}
    # a controller's view: each cycle's command against the latest state it had read
    seen_errors, state_ages = [], []
    for run in recorded['runs']:
        t0, start, goal, duration = run['t0'], run['start'], run['goal'], run['duration']
        for now, stamp, position in recorded['seen']:
            t = now - t0
            if 0.0 <= t <= duration + SETTLE_S:
                s = min(t / duration, 1.0)
                desired = start + (goal - start) * s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s)
                seen_errors.append(abs(position - desired))
                state_ages.append(now - stamp)
    peak = rest_to_rest_peak_speed(0.0, AMPLITUDE, DURATION_S)
    period = 1.0 / UPDATE_RATE_HZ
    bound = peak * period + peak ** 2 / (2.0 * acceleration) if speed_limit >= peak \
        else math.inf
    ordered = sorted(errors)
    results = {
        'joint': joint, 'runs': len(recorded['runs']),
        'trajectory': f'{AMPLITUDE:g} in {DURATION_S:g} s (quintic, peak {peak:.3f}/s), '
                      f'{UPDATE_RATE_HZ:g} Hz',
        'samples': len(ordered),
        'published_of_cycles': f'{recorded["published"]} of {recorded["cycles"]}',
        'error_p50': round(statistics.median(ordered), 4) if ordered else None,
        'error_p99': round(ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))], 4)
        if ordered else None,
        'error_max': round(ordered[-1], 4) if ordered else None,
        'worst': worst,
        'device_speed_limit': round(speed_limit, 4),
        'device_acceleration': round(acceleration, 4),
        'allowed_by_device_limits': round(bound, 4),
        'allowed_terms': {'one_control_period': round(peak * period, 4),
                          'acceleration': round(peak ** 2 / (2.0 * acceleration), 4)},
    }
    results['within_allowed'] = bool(ordered) and ordered[-1] <= bound
    if recorded.get('late'):
        late = sorted(recorded['late'])
        results['publisher_late_ms'] = {
            'p99': round(late[min(len(late) - 1, round(0.99 * (len(late) - 1)))] * 1e3, 1),
            'max': round(late[-1] * 1e3, 1)}
    if seen_errors:
        results['controller_view'] = {
            'error_max': round(max(seen_errors), 4),
            'state_age_p50_ms': round(statistics.median(state_ages) * 1e3, 1),
            'state_age_max_ms': round(max(state_ages) * 1e3, 1)}
    return results


if __name__ == '__main__':  # python bench/tracking.py [driver ...]: tracking alone
    from gimbal_driver_common.registry import drivers
    from gimbal_driver_testing import DomainLease

    chosen = sys.argv[1:]
    report = {}
    with DomainLease() as lease:
        for spec in drivers():
            if not chosen or spec.name in chosen:
                freeze_heap()
                report[spec.name] = tracking_figures(spec, lease)
    print(json.dumps(report, indent=2))
