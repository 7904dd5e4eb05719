"""The U-Camera driver's own step in ``scripts/demo.py`` (named in its registry spec); it
waits through the demo's ROS client, so it imports no test support."""

from __future__ import annotations

from typing import Any

from std_msgs.msg import Float64


def zoom(target: Any, ros: Any) -> str:
    """Zoom to half tele; repeat the command until the gimbal reports it (a single message
    right after discovery can be lost).

    The deadline is an outer one: in a run pinned to one core the node took the command
    7 s after the first was published, and ~/zoom did not reach this new subscription in
    the 15 s the step had then (docs/testing.md). The wait ends as soon as it is seen."""
    zooms = ros.subscribe(target.ns('zoom'), Float64)

    def reached() -> bool:
        ros.publish(target.ns('zoom_command'), Float64(data=0.5))
        return any(abs(m.data - 0.5) < 1e-3 for m in list(zooms)) or target.stop.is_set()

    ros.wait_for(reached, 60, 'the reported zoom 0.5', interval=0.2)
    return 'zoom 0.5 commanded on ~/zoom_command and reported on ~/zoom'
