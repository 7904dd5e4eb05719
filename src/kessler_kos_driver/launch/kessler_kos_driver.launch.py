"""Launch the Kessler kOS driver as a managed (lifecycle) node.

ros2 launch kessler_kos_driver kessler_kos_driver.launch.py [params_file:=...] [autostart:=true]
use_description:=true also starts robot_state_publisher with urdf/kessler_kos_driver.urdf
(or description_file:=...), which the node uses for ~/look_at too.
sim:=true also starts kessler_kos_sim --precalibrated on TCP 127.0.0.1:5520
(config/kessler_kos_driver_sim.yaml).
Uses launch/launch_ros, which a full ROS 2 install provides (not the pip environment).
"""

from gimbal_driver_common.ros.description_launch import driver_launch_description


def generate_launch_description():
    return driver_launch_description('kessler_kos_driver')
