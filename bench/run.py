"""``make bench``: run every driver benchmark and print one JSON document.

Each ``bench/bench_<name>.py`` has ``run(domain_id) -> dict``. The rclpy
reference and the loopback round trip are measured first, in the same run.
The JSON is also written to ``bench_output/bench.json``; ``--markdown`` prints
the README table from it.
"""

from __future__ import annotations

import argparse
import importlib
import json
import platform
import sys
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from harness import ROOT, git_revision, loopback_rtt_us, rclpy_reference  # noqa: E402

from gimbal_driver_common.testing import DomainLease  # noqa: E402


def benchmarks() -> list[str]:
    return sorted(p.stem.removeprefix('bench_') for p in HERE.glob('bench_*.py'))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('names', nargs='*', help=f'subset of {benchmarks()}')
    parser.add_argument('--markdown', action='store_true', help='print the README table')
    args = parser.parse_args()
    output = ROOT / 'bench_output' / 'bench.json'
    if args.markdown:
        print(markdown(json.loads(output.read_text())))
        return 0
    results: dict = {
        'revision': git_revision(),
        'date': time.strftime('%Y-%m-%dT%H:%M:%S'),
        'machine': f'{platform.machine()} {platform.processor() or ""}'.strip(),
        'python': platform.python_version(),
    }
    with DomainLease() as domain:
        results['reference'] = {
            'loopback_tcp_rtt_us': loopback_rtt_us(),
            'rclpy_joint_state_pubsub_100hz': rclpy_reference(domain),
        }
        for name in args.names or benchmarks():
            print(f'bench: {name} ...', file=sys.stderr, flush=True)
            try:
                module = importlib.import_module(f'bench_{name}')
                results[name] = module.run(domain)
            except Exception as exc:  # noqa: BLE001 - one failing bench must not hide the others
                traceback.print_exc()
                results[name] = {'error': f'{type(exc).__name__}: {exc}'}
    output.parent.mkdir(exist_ok=True)
    output.write_text(json.dumps(results, indent=2))
    print(json.dumps(results, indent=2))
    return 0 if not any('error' in v for v in results.values() if isinstance(v, dict)) else 1


def markdown(results: dict) -> str:
    """The README table: one row per figure, with its reference."""
    ref = results['reference']['rclpy_joint_state_pubsub_100hz']
    rows = ['| driver | figure | measured | reference (same run) | target |',
            '|---|---|---|---|---|']
    for name, data in results.items():
        if not isinstance(data, dict) or name == 'reference':
            continue
        if 'error' in data:
            rows.append(f'| {name} | error | {data["error"]} | | |')
            continue
        codec = data.get('codec', {})
        for key, value in codec.items():
            if key.endswith('_per_s') and not key.startswith('wire'):
                wire = codec.get('wire_limit_frames_per_s')
                rows.append(f'| {name} | codec {key} | {value:,.0f} | wire limit {wire:,.0f} '
                            f'frames/s | ≥ 100,000 |')
        latency = data.get('sim_to_subscriber')
        if latency:
            rows.append(f'| {name} | sim→subscriber latency p50/p99 | {latency["p50_ms"]} / '
                        f'{latency["p99_ms"]} ms | rclpy pub/sub {ref["latency"]["p50_ms"]} / '
                        f'{ref["latency"]["p99_ms"]} ms | p99 < 5 ms |')
        command = data.get('command_latency')
        if command and command.get('n'):
            rows.append(f'| {name} | joint_command→simulator p50/p99 | {command["p50_ms"]} / '
                        f'{command["p99_ms"]} ms | rclpy pub/sub {ref["latency"]["p50_ms"]} / '
                        f'{ref["latency"]["p99_ms"]} ms | |')
        if 'joint_states_hz' in data:
            rows.append(f'| {name} | joint_states rate at publish_rate '
                        f'{data.get("publish_rate")} Hz | {data["joint_states_hz"]} Hz | rclpy '
                        f'{ref["achieved_hz"]} Hz at {ref["rate_hz"]:g} Hz | '
                        f'{data.get("rate_target", "")} |')
        if 'cpu_percent' in data:
            rows.append(f'| {name} | node CPU at default rate | {data["cpu_percent"]} % | rclpy '
                        f'publisher {ref["cpu_percent"]} % at {ref["rate_hz"]:g} Hz | < 10 % |')
    return '\n'.join(rows)


if __name__ == '__main__':
    sys.exit(main())
