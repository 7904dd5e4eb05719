"""Infrastructure shared by every gimbal driver in this workspace.

The modules at the top level import nothing from ROS, so protocol clients, device
adapters and simulators use them in plain Python; everything that needs rclpy lives in
:mod:`gimbal_driver_common.ros`. Test support (process and ROS test helpers, the
conformance suites) is the package :mod:`gimbal_driver_testing`, which runtime code never
imports; the in-process simulator handles' base (:mod:`gimbal_driver_common.sim_handle`)
is simulator support and stays here.
"""
