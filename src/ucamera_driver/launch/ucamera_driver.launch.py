"""Launch the U-Camera driver (and optionally the simulator) on a full ROS 2 install.

    ros2 launch ucamera_driver ucamera_driver.launch.py serial_port:=/dev/ttyUSB0
    ros2 launch ucamera_driver ucamera_driver.launch.py sim:=true
    ros2 launch ucamera_driver ucamera_driver.launch.py params_file:=/path/robot.yaml
    ros2 launch ucamera_driver ucamera_driver.launch.py use_description:=true  # TF from URDF

Managed bring-up: pass autostart:=false and drive the lifecycle yourself
(configure opens the port and reads the version; activate starts publishing).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node

from gimbal_driver_common.ros.description_launch import description_actions, description_parameter

SIM_LINK = "/tmp/ucamera_sim_tty"


def _nodes(context):
    share = get_package_share_directory("ucamera_driver")
    sim = LaunchConfiguration("sim").perform(context).lower() == "true"
    params_file = LaunchConfiguration("params_file").perform(context) or os.path.join(
        share, "config", "ucamera_driver_sim.yaml" if sim else "ucamera_driver.yaml")
    overrides = {
        "autostart": LaunchConfiguration("autostart").perform(context).lower() == "true"}
    serial_port = LaunchConfiguration("serial_port").perform(context)
    if serial_port:
        overrides["serial_port"] = serial_port
    actions = []
    if sim:
        actions.append(Node(package="ucamera_driver", executable="ucamera_sim",
                            name="ucamera_sim", arguments=["--link", SIM_LINK],
                            output="screen"))
    actions.append(LifecycleNode(
        package="ucamera_driver", executable="ucamera_driver_node", name="ucamera_driver",
        namespace="", output="screen",
        parameters=[params_file, overrides, description_parameter()],
    ))
    return actions


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("sim", default_value="false",
                              description="also start ucamera_sim and connect to it"),
        DeclareLaunchArgument("params_file", default_value="",
                              description="parameter YAML ('' = the packaged one)"),
        DeclareLaunchArgument("serial_port", default_value="",
                              description="override serial_port ('' = from the YAML)"),
        DeclareLaunchArgument("autostart", default_value="true",
                              description="false for managed lifecycle bring-up"),
        OpaqueFunction(function=_nodes),
        *description_actions("ucamera_driver"),
    ])
