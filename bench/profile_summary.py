"""Summarise a py-spy raw profile (collapsed stacks, ``--threads``): where a node's time goes.

``make bench`` with ``BENCH_PROFILE_DIR=DIR`` writes one ``<node>_50hz_cpu.txt`` (samples of
threads on a CPU) and one ``<node>_50hz_gil.txt`` (samples of the thread holding the GIL)
per driver while the node receives the 50 Hz command stream. This prints, per file, the
share of samples per thread and the functions with the largest inclusive and self shares.

Usage: python bench/profile_summary.py FILE... [--top N]
"""

from __future__ import annotations

import argparse
import re
from collections import Counter
from pathlib import Path

#: py-spy writes "thread (0x7f..): name" or "thread (1234): name" as the first frame
THREAD = re.compile(r'^thread \((?:0x)?[0-9a-f]+\)(?:: )?(?P<name>.*)$')


def parse(path: Path) -> list[tuple[str, list[str], int]]:
    """(thread name, frames root first, samples) per line of a collapsed-stack file."""
    stacks = []
    for line in path.read_text().splitlines():
        stack, _, count = line.rpartition(' ')
        if not stack:
            continue
        frames = stack.split(';')
        match = THREAD.match(frames[0])
        thread = match['name'] if match else frames[0]
        # worker threads differ only by their suffix: one row for rclpy's pool
        thread = re.sub(r'_\d+$', '_*', thread or 'main')
        stacks.append((thread, frames[1:], int(count)))
    return stacks


def summary(path: Path, top: int) -> str:
    stacks = parse(path)
    total = sum(count for _, _, count in stacks) or 1
    threads: Counter[str] = Counter()
    inclusive: Counter[str] = Counter()
    own: Counter[str] = Counter()
    for thread, frames, count in stacks:
        threads[thread] += count
        for frame in set(frames):
            inclusive[frame] += count
        if frames:
            own[frames[-1]] += count
    lines = [f'{path.name}: {total} samples']
    lines.append('  threads:')
    lines += [f'    {100 * n / total:5.1f} %  {name}' for name, n in threads.most_common()]
    lines.append(f'  inclusive (top {top}):')
    lines += [f'    {100 * n / total:5.1f} %  {name}' for name, n in inclusive.most_common(top)]
    lines.append(f'  self (top {top}):')
    lines += [f'    {100 * n / total:5.1f} %  {name}' for name, n in own.most_common(top)]
    return '\n'.join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('files', nargs='+', type=Path)
    parser.add_argument('--top', type=int, default=25)
    args = parser.parse_args()
    for path in args.files:
        print(summary(path, args.top))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
