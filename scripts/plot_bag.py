"""Plot commanded vs. actual joint positions per driver from a demo MCAP bag.

Actual positions come from each driver's ``<ns>/joint_states``; commanded ones
from the ``target_position`` of each axis in ``<ns>/<node>/status`` (the last
move target the driver sent). One PNG with a row of axes per driver.

    python scripts/plot_bag.py demo_output/demo.mcap demo_output/positions.png
"""

from __future__ import annotations

import math
import sys
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

Series = dict[str, list[tuple[float, float]]]


def read_series(bag: Path) -> tuple[dict[str, Series], dict[str, Series]]:
    """(actual, commanded): namespace -> joint -> [(t, position)]."""
    actual: dict[str, Series] = defaultdict(lambda: defaultdict(list))
    commanded: dict[str, Series] = defaultdict(lambda: defaultdict(list))
    with bag.open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, msg in reader.iter_decoded_messages():
            t = message.log_time / 1e9
            topic = channel.topic
            if topic.endswith('/joint_states'):
                ns = topic.rsplit('/', 1)[0] or '/'
                for name, position in zip(msg.name, msg.position, strict=False):
                    actual[ns][name].append((t, position))
            elif topic.endswith('/status') and hasattr(msg, 'axes'):
                ns = topic.rsplit('/', 2)[0] or '/'
                for axis in msg.axes:
                    if not math.isnan(axis.target_position):
                        commanded[ns][axis.name].append((t, axis.target_position))
    return actual, commanded


def plot(bag: Path, out: Path) -> Path:
    actual, commanded = read_series(bag)
    namespaces = sorted(actual)
    if not namespaces:
        raise SystemExit(f'{bag}: no joint_states recorded')
    t0 = min(points[0][0] for ns in namespaces for points in actual[ns].values() if points)
    fig, axes = plt.subplots(len(namespaces), 1, figsize=(10, 3.2 * len(namespaces)),
                             squeeze=False)
    for row, ns in enumerate(namespaces):
        ax = axes[row][0]
        for index, (joint, points) in enumerate(sorted(actual[ns].items())):
            color = f'C{index}'
            ax.plot([p[0] - t0 for p in points], [p[1] for p in points], color=color,
                    label=f'{joint} actual')
            targets = commanded[ns].get(joint, [])
            if targets:
                ax.step([p[0] - t0 for p in targets], [p[1] for p in targets], where='post',
                        color=color, linestyle='--', label=f'{joint} commanded')
        ax.set_title(f'{ns}: commanded vs. actual joint positions')
        ax.set_xlabel('time [s]')
        ax.set_ylabel('position [rad or m]')
        ax.grid(True, alpha=0.3)
        ax.legend(loc='upper right', fontsize='small', ncol=2)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def main() -> int:
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    print(f'plot_bag: wrote {plot(Path(sys.argv[1]), Path(sys.argv[2]))}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
