"""Launch the reference virtual gimbal driver as a managed (lifecycle) node.

ros2 launch virtual_gimbal_driver virtual_gimbal_driver.launch.py [sim:=true]
    [params_file:=...] [autostart:=true] [namespace:=...] [use_description:=true]
    [description_file:=...]
Its device is its simulator: run `ros2 run virtual_gimbal_driver virtual_gimbal_sim` first,
or pass sim:=true to start it (TCP 127.0.0.1:4950, config/virtual_gimbal_driver.yaml).
Uses launch/launch_ros, which a full ROS 2 install provides (not the pip environment).
"""

from gimbal_driver_common.ros.description_launch import driver_launch_description


def generate_launch_description():
    return driver_launch_description('virtual_gimbal_driver')
