"""Launch the Capture pedestal driver as a managed (lifecycle) node.

ros2 launch capture_driver capture_driver.launch.py [params_file:=...] [autostart:=true]
With autostart false (the default here) a lifecycle manager configures and activates it.
use_description:=true also starts robot_state_publisher with urdf/capture_driver.urdf
(or description_file:=...), which the node uses for ~/look_at too.
sim:=true also starts capture_sim on TCP 127.0.0.1:4949 (config/capture_driver_sim.yaml).
Uses launch/launch_ros, which a full ROS 2 install provides (not the pip environment).
"""

from gimbal_driver_common.ros.description_launch import driver_launch_description


def generate_launch_description():
    return driver_launch_description('capture_driver')
