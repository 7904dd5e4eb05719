"""Infrastructure shared by every gimbal driver in this workspace.

The modules at the top level import nothing from ROS, so protocol clients and
simulators can use them in plain Python; everything that needs rclpy lives in
:mod:`gimbal_driver_common.ros`.
"""
