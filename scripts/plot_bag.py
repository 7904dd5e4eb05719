"""Plot commanded vs. actual joint positions per driver from a rosbag2 bag.

Reads any rosbag2 bag (the demo's, ``scripts/record_bag.py``'s or one from
``ros2 bag record``, MCAP or SQLite storage) with the ``rosbags`` reader, which
decodes every message by the definitions stored in the bag. Actual positions
come from each ``<ns>/joint_states`` (sensor_msgs/msg/JointState). One PNG with a
row of axes per driver.

What was commanded comes from the demo's ``demo_commands.json`` when it is given
(``scripts/demo.py`` writes it: each step's name and span, move and preset targets,
jog velocities, scan corners, homing, playback key frames). Without it, the dashed
line is each axis' ``target_position`` in ``<ns>/<node>/status``
(gimbal_msgs/msg/GimbalStatus): the last target the driver sent, which motions the
device runs by itself (its scans, homing, playback) do not change.

Below a driver's positions, a row of motor current in A (``AxisState.current`` in
``~/status``, for devices that report it) and a row of effort as torque in N*m (N for a
linear axis; joint_states ``effort``, published only when the node's ``torque_constants``
are set), each where the bag has any.

    python scripts/plot_bag.py BAG OUT.png [COMMANDS.json]
    python scripts/plot_bag.py demo_output/demo_bag /tmp/plot.png demo_output/demo_commands.json
"""

from __future__ import annotations

import json
import math
import sys
import textwrap
from collections import defaultdict
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
from rosbags.highlevel import AnyReader

JOINT_STATE = 'sensor_msgs/msg/JointState'
GIMBAL_STATUS = 'gimbal_msgs/msg/GimbalStatus'
Series = dict[str, list[tuple[float, float]]]


class BagSeries:
    """namespace -> joint -> [(t, value)] of each quantity the plot shows."""

    def __init__(self) -> None:
        self.actual: dict[str, Series] = defaultdict(_series)
        self.commanded: dict[str, Series] = defaultdict(_series)
        #: motor current, A (~/status AxisState.current)
        self.current: dict[str, Series] = defaultdict(_series)
        #: torque, N*m or N (joint_states effort)
        self.effort: dict[str, Series] = defaultdict(_series)


def _series() -> Series:
    return defaultdict(list)


def read_bag(bag: Path) -> BagSeries:
    """Every joint_states and ~/status message of the bag, by driver namespace."""
    series = BagSeries()
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
                    series.actual[ns][name].append((t, float(position)))
                for name, effort in zip(msg.name, msg.effort, strict=False):
                    if math.isfinite(effort):
                        series.effort[ns][name].append((t, float(effort)))
            else:
                ns = topic.rsplit('/', 2)[0] or '/'
                for axis in msg.axes:
                    if not math.isnan(axis.target_position):
                        series.commanded[ns][axis.name].append((t, axis.target_position))
                    current = getattr(axis, 'current', math.nan)  # absent in older bags
                    if math.isfinite(current):
                        series.current[ns][axis.name].append((t, float(current)))
    return series


def read_series(bag: Path) -> tuple[dict[str, Series], dict[str, Series]]:
    """(actual, commanded): namespace -> joint -> [(t, position)]."""
    series = read_bag(bag)
    return series.actual, series.commanded


#: the rows under a driver's positions: (BagSeries field, y label, title)
EXTRA_ROWS = (
    ('current', 'motor current [A]', 'motor current (~/status AxisState.current)'),
    ('effort', 'effort (torque) [N·m; N linear]',
     'effort = current x torque_constants (joint_states)'),
)


CAPTION = ('Solid: the position each joint reported (joint_states). Dashed: what the demo '
           'commanded, held until the next command: move and preset targets, scan corners '
           '(two dashed limits), playback key frames (dots, joined as the device plays them); '
           'a shaded span in a joint\'s colour is a jog at the velocity written in it, a '
           'triangle is a homing command. Grey bands are the demo steps, named at the top.')


def load_commands(path: Path | None) -> dict[str, list[dict[str, Any]]]:
    """namespace -> the demo's command records (``DemoTarget.commanded``), in time order."""
    if path is None or not path.is_file():
        return {}
    by_ns: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for record in sorted(json.loads(path.read_text()), key=lambda r: r.get('t0', r['t'])):
        by_ns[record['ns']].append(record)
    return by_ns


def commanded_lines(records: list[dict[str, Any]], joint: str,
                    t0: float) -> tuple[list[float], list[float], list[tuple[float, float]]]:
    """One joint's held targets as a step line (x, y; NaN where a jog, scan, homing or
    playback took over) and its key frames as (x, y) dots."""
    xs: list[float] = []
    ys: list[float] = []
    dots: list[tuple[float, float]] = []

    def point(at: float, value: float) -> None:
        xs.append(at - t0)
        ys.append(value)

    for record in records:
        kind = record['kind']
        if kind == 'target' and joint in record['positions']:
            point(record['t'], record['positions'][joint])
        elif (kind == 'jog' and record['joint'] == joint) or (
                kind == 'scan' and joint in record['corners']):
            point(record['t0'], math.nan)
        elif kind == 'home':
            point(record['t'], math.nan)
        elif kind == 'keyframes' and joint in record['joint_names']:
            index = record['joint_names'].index(joint)
            point(record['t'], math.nan)
            frames = [(record['t'] + seconds - t0, values[index])
                      for seconds, values in record['points']]
            dots.extend(frames)
            point(frames[-1][0] + t0, frames[-1][1])  # where the playback ends
    return xs, ys, dots


def draw_commands(ax: Any, records: list[dict[str, Any]], joints: list[str], t0: float,
                  t_end: float) -> None:
    steps = [r for r in records if r['kind'] == 'step']
    for index, step in enumerate(steps):
        ax.axvspan(step['t0'] - t0, step['t1'] - t0, color='0.5',
                   alpha=0.10 if index % 2 == 0 else 0.18, lw=0)
        ax.text((step['t0'] + step['t1']) / 2 - t0, 1.01, step['name'], ha='center',
                va='bottom', fontsize='x-small', transform=ax.get_xaxis_transform())
    for index, joint in enumerate(joints):
        color = f'C{index}'
        xs, ys, dots = commanded_lines(records, joint, t0)
        if xs:
            xs.append(t_end - t0), ys.append(ys[-1])
            ax.step(xs, ys, where='post', color=color, linestyle='--',
                    label=f'{joint} commanded')
        if dots:
            ax.plot([d[0] for d in dots], [d[1] for d in dots], 'o', color=color,
                    markersize=4)
            # the device plays the key frames as a smooth curve: join them
            ax.plot([d[0] for d in dots], [d[1] for d in dots], ':', color=color)
        for record in records:
            if record['kind'] == 'jog' and record['joint'] == joint:
                ax.axvspan(record['t0'] - t0, record['t1'] - t0, color=color, alpha=0.25,
                           lw=0)
                ax.text((record['t0'] + record['t1']) / 2 - t0, 0.04,
                        f'{joint} jog {record["velocity"]:+g} rad/s', ha='center',
                        fontsize='x-small', color=color, transform=ax.get_xaxis_transform())
            elif record['kind'] == 'scan' and joint in record['corners']:
                for limit in record['corners'][joint]:
                    ax.hlines(limit, record['t0'] - t0, record['t1'] - t0, colors=color,
                              linestyles='--')
            elif record['kind'] == 'home' and index == 0:
                ax.plot([record['t'] - t0], [0.96], 'v', color='k',
                        transform=ax.get_xaxis_transform())


def draw_extra_row(ax: Any, ns: str, quantity: str, by_joint: Series, joints: list[str],
                   t0: float) -> None:
    """One driver's motor current (A) or effort (torque) per joint, labelled with its unit
    and where it came from."""
    _, ylabel, title = next(row for row in EXTRA_ROWS if row[0] == quantity)
    for index, joint in enumerate(joints):
        points = by_joint.get(joint, [])
        if points:
            ax.plot([p[0] - t0 for p in points], [p[1] for p in points], color=f'C{index}',
                    label=f'{joint} {quantity}')
    ax.set_title(f'{ns}: {title}', pad=6)
    ax.set_xlabel('time [s]')
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend(loc='upper left', bbox_to_anchor=(1.005, 1.0), fontsize='small')


def rows_of(series: BagSeries) -> list[tuple[str, str]]:
    """The figure's rows: (namespace, '' for its positions or an EXTRA_ROWS quantity)."""
    rows: list[tuple[str, str]] = []
    for ns in sorted(series.actual):
        rows.append((ns, ''))
        rows.extend((ns, name) for name, _, _ in EXTRA_ROWS if getattr(series, name).get(ns))
    return rows


def plot(bag: Path, out: Path, commands: Path | None = None) -> Path:
    series = read_bag(bag)
    if not series.actual:
        raise SystemExit(f'{bag}: no joint_states recorded')
    fig = figure(series, load_commands(commands))
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def figure(series: BagSeries, by_ns: dict[str, list[dict[str, Any]]]) -> Any:
    """The matplotlib figure of a bag's series (and the demo's commands, if any)."""
    actual = series.actual
    namespaces = sorted(actual)
    t0 = min(points[0][0] for ns in namespaces for points in actual[ns].values() if points)
    t_end = max(points[-1][0] for ns in namespaces for points in actual[ns].values() if points)
    rows = rows_of(series)
    fig, axes = plt.subplots(len(rows), 1, figsize=(13, 3.4 * len(rows) + 0.8),
                             squeeze=False)
    for row, (ns, quantity) in enumerate(rows):
        ax = axes[row][0]
        joints = sorted(actual[ns])
        if quantity:
            draw_extra_row(ax, ns, quantity, getattr(series, quantity)[ns], joints, t0)
            continue
        for index, joint in enumerate(joints):
            points = actual[ns][joint]
            ax.plot([p[0] - t0 for p in points], [p[1] for p in points], color=f'C{index}',
                    label=f'{joint} actual')
        if by_ns:
            draw_commands(ax, by_ns.get(ns, []), joints, t0, t_end)
        else:
            for index, joint in enumerate(joints):
                targets = series.commanded[ns].get(joint, [])
                if targets:
                    ax.step([p[0] - t0 for p in targets], [p[1] for p in targets],
                            where='post', color=f'C{index}', linestyle='--',
                            label=f'{joint} last target sent (~/status)')
        ax.set_title(f'{ns}: commanded vs. actual joint positions', pad=14)
        ax.set_xlabel('time [s]')
        ax.set_ylabel('position [rad or m]')
        ax.grid(True, alpha=0.3)
        ax.legend(loc='upper left', bbox_to_anchor=(1.005, 1.0), fontsize='small')
    caption = CAPTION if by_ns else (
        'Solid: the position each joint reported (joint_states). Dashed: the last target '
        'the driver sent (~/status target_position); motions the device runs by itself '
        '(its scans, homing, playback) do not change it.')
    if any(quantity for _, quantity in rows):
        caption += (' Current rows: motor current in A (~/status AxisState.current). Effort '
                    'rows: torque in N·m (N for a linear axis), current x the node\'s '
                    'torque_constants (joint_states effort).')
    fig.text(0.01, 0.005, textwrap.fill(caption, 150), fontsize='small', va='bottom')
    fig.tight_layout(rect=(0, 0.7 / fig.get_figheight(), 1, 1))
    return fig


def main() -> int:
    if len(sys.argv) not in (3, 4):
        print(__doc__, file=sys.stderr)
        return 2
    commands = Path(sys.argv[3]) if len(sys.argv) == 4 else None
    print(f'plot_bag: wrote {plot(Path(sys.argv[1]), Path(sys.argv[2]), commands)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
