"""Where the pedestal must point to look at a geographic target (GPS_GoToTarget, 4.4.11).

The spec does not give the controller's formula; this is the local flat-earth
(equirectangular) approximation, good for the ranges a pedestal aims at. The simulator
uses it to execute GPS_GoToTarget and the node to check the resulting pose against the
joint limits before it sends the target.
"""

from __future__ import annotations

import math

from .datatypes import GeoPoint

EARTH_RADIUS_M = 6371000.0


def aim_at(origin: GeoPoint, heading_deg: float, target: GeoPoint) -> tuple[float, float]:
    """(pan, tilt) in device degrees: pan clockwise from the system heading, tilt up."""
    lat0 = math.radians(origin.latitude)
    north = math.radians(target.latitude - origin.latitude) * EARTH_RADIUS_M
    east = math.radians(target.longitude - origin.longitude) * EARTH_RADIUS_M * math.cos(lat0)
    up = target.altitude - origin.altitude
    bearing = math.degrees(math.atan2(east, north))
    pan = (bearing - heading_deg + 180.0) % 360.0 - 180.0
    tilt = math.degrees(math.atan2(up, math.hypot(north, east)))
    return pan, tilt
