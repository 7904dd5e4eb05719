"""Plot commanded vs. actual joint positions per driver from a rosbag2 bag.

Reads any rosbag2 bag (the demo's, ``scripts/record_bag.py``'s or one from
``ros2 bag record``, MCAP or SQLite storage) with the ``rosbags`` reader, which
decodes every message by the definitions stored in the bag. Actual positions
come from each ``<ns>/joint_states`` (sensor_msgs/msg/JointState); commanded
ones from the ``target_position`` of each axis in ``<ns>/<node>/status``
(gimbal_msgs/msg/GimbalStatus: the last move target the driver sent). One PNG
with a row of axes per driver.

    python scripts/plot_bag.py demo_output/demo_bag demo_output/positions.png
"""

from __future__ import annotations

import math
import sys
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
from rosbags.highlevel import AnyReader

JOINT_STATE = 'sensor_msgs/msg/JointState'
GIMBAL_STATUS = 'gimbal_msgs/msg/GimbalStatus'
Series = dict[str, list[tuple[float, float]]]


def read_series(bag: Path) -> tuple[dict[str, Series], dict[str, Series]]:
    """(actual, commanded): namespace -> joint -> [(t, position)]."""
    actual: dict[str, Series] = defaultdict(lambda: defaultdict(list))
    commanded: dict[str, Series] = defaultdict(lambda: defaultdict(list))
    with AnyReader([bag]) as reader:
        wanted = [c for c in reader.connections
                  if c.msgtype in (JOINT_STATE, GIMBAL_STATUS)]
        for connection, stamp, raw in reader.messages(connections=wanted):
            msg = reader.deserialize(raw, connection.msgtype)
            t = stamp / 1e9
            topic = connection.topic
            if connection.msgtype == JOINT_STATE:
                ns = topic.rsplit('/', 1)[0] or '/'
                for name, position in zip(msg.name, msg.position, strict=False):
                    actual[ns][name].append((t, float(position)))
            else:
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
