"""A compass heading as sensor_msgs/Imu, the way ublox_gps publishes its navheading.

Capture's GPS heading and the turret's rover heading / global yaw share this one
convention, so a consumer (robot_localization, a plotter) reads every driver alike.
"""

from __future__ import annotations

import math

from sensor_msgs.msg import Imu

#: orientation variance (rad^2) of an angle the message does not measure, or of an
#: unknown heading accuracy: large, so a filter gives it no weight
UNMEASURED_ANGLE_VARIANCE = 1e6
#: REP-145: -1 in element 0 of a covariance marks the quantity as not provided
NOT_PROVIDED = -1.0


def heading_imu(heading_rad: float, accuracy_rad: float | None) -> Imu:
    """Yaw-only Imu in ENU from a compass heading (clockwise from north).

    REP-103 yaw counts counter-clockwise from east, so yaw = pi/2 - heading. The
    accuracy (1 sigma) squared goes to orientation_covariance[8]; None (or <= 0) means
    unknown and gives :data:`UNMEASURED_ANGLE_VARIANCE`. The caller sets the header.
    """
    yaw = math.remainder(math.pi / 2.0 - heading_rad, math.tau)
    msg = Imu()
    msg.orientation.z = math.sin(yaw / 2.0)
    msg.orientation.w = math.cos(yaw / 2.0)
    yaw_variance = (accuracy_rad ** 2 if accuracy_rad is not None and accuracy_rad > 0.0
                    else UNMEASURED_ANGLE_VARIANCE)
    msg.orientation_covariance = [UNMEASURED_ANGLE_VARIANCE, 0.0, 0.0,
                                  0.0, UNMEASURED_ANGLE_VARIANCE, 0.0,
                                  0.0, 0.0, yaw_variance]
    msg.angular_velocity_covariance[0] = NOT_PROVIDED
    msg.linear_acceleration_covariance[0] = NOT_PROVIDED
    return msg
