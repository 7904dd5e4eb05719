"""The turret's own step in ``scripts/demo.py`` (named in its registry spec)."""

from __future__ import annotations

from typing import Any

from sensor_msgs.msg import NavSatFix
from std_srvs.srv import SetBool


def cover_and_fix(target: Any, ros: Any) -> str:
    """Open the cover and wait for a GNSS fix from the turret."""
    reply = ros.call(SetBool, target.ns('set_cover'), SetBool.Request(data=True))
    if not reply.success:
        raise RuntimeError(reply.message)
    fix = ros.wait_for_message(target.ns('fix'), NavSatFix, timeout=60)  # an outer deadline
    return (f'set_cover true: {reply.message}; GNSS fix {fix.latitude:.4f}, '
            f'{fix.longitude:.4f}, {fix.altitude:.1f} m')
