"""Where the pedestal must point to look at a geographic target (GPS_GoToTarget, 4.4.11).

The spec does not give the controller's formula. This uses the WGS84 geodesy of
``~/look_at_geo`` (pymap3d: geodetic -> ECEF -> the local ENU frame at the pedestal), so
the simulator's go-to-target and the driver's own check of the pose agree; the earlier
flat-earth approximation on a sphere was up to 0.09 deg off in azimuth at mid latitudes
(the ratio of the meridian and prime-vertical radii). The simulator uses it to execute
GPS_GoToTarget, and the node to check the resulting pose against the joint limits before
it sends the target (``~/goto_lla``, ``~/start_target_loop``).
"""

from __future__ import annotations

import math

from .datatypes import GeoPoint


def aim_at(origin: GeoPoint, heading_deg: float, target: GeoPoint) -> tuple[float, float]:
    """(pan, tilt) in device degrees: pan clockwise from the system heading, tilt up.

    pymap3d is imported at the first geographic aim, not with the node (2.7 MB of PSS
    with its dependencies; bench/README.md, "What a node imports")."""
    import pymap3d

    east, north, up = pymap3d.geodetic2enu(
        target.latitude, target.longitude, target.altitude,
        origin.latitude, origin.longitude, origin.altitude)
    bearing = math.degrees(math.atan2(east, north))
    pan = (bearing - heading_deg + 180.0) % 360.0 - 180.0
    tilt = math.degrees(math.atan2(up, math.hypot(north, east)))
    return pan, tilt
