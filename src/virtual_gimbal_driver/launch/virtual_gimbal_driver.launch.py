"""Launch the reference virtual gimbal driver.

ros2 launch virtual_gimbal_driver virtual_gimbal_driver.launch.py
"""

from gimbal_driver_common.ros.description_launch import driver_launch_description


def generate_launch_description():
    return driver_launch_description('virtual_gimbal_driver')
