"""Infrastructure shared by every gimbal driver in this workspace.

The modules at the top level import nothing from ROS, so protocol clients, device
adapters and simulators use them in plain Python; everything that needs rclpy lives in
:mod:`gimbal_driver_common.ros`. Test scaffolding (process and ROS test helpers, the
conformance suite, the in-process simulator handles) lives in
:mod:`gimbal_driver_common.testing`, which runtime code never imports.
"""
