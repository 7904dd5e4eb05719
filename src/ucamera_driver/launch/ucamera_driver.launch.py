"""Launch the U-Camera driver as a managed (lifecycle) node.

ros2 launch ucamera_driver ucamera_driver.launch.py [params_file:=...] [autostart:=true]
    [namespace:=...] [use_description:=true] [description_file:=...] [sim:=true]
With autostart false (the default) a lifecycle manager configures and activates it. The
serial port is the params file's serial_port (config/ucamera_driver.yaml: /dev/ttyUSB0).
sim:=true also starts ucamera_sim on /tmp/ucamera_sim_tty (config/ucamera_driver_sim.yaml).
Uses launch/launch_ros, which a full ROS 2 install provides (not the pip environment).
"""

from gimbal_driver_common.ros.description_launch import driver_launch_description


def generate_launch_description():
    return driver_launch_description('ucamera_driver')
