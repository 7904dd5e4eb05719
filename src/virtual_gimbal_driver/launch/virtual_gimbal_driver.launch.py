"""Launch the reference virtual gimbal driver as a managed (lifecycle) node.

    ros2 launch virtual_gimbal_driver virtual_gimbal_driver.launch.py [name:=value ...]

Arguments (default after :=; docs/interface.md, "Launch arguments"):
    params_file:=''          parameter YAML; '' = config/virtual_gimbal_driver.yaml, or
                             config/virtual_gimbal_driver_sim.yaml with sim:=true
    autostart:=true          the node configures and activates itself; false: a lifecycle
                             manager (or ros2 lifecycle set) does
    namespace:=''            namespace of the node and of robot_state_publisher
    use_description:=false   true: also start robot_state_publisher with the URDF (TF)
    description_file:=share/virtual_gimbal_driver/urdf/virtual_gimbal_driver.urdf
                             the URDF robot_state_publisher publishes and ~/look_at aims with
    sim:=false               true: also start virtual_gimbal_sim on TCP 127.0.0.1:4950
                             (config/virtual_gimbal_driver_sim.yaml)
    log_level:=''            the node's --ros-args --log-level: debug, info, warn, error,
                             fatal, or logger:=level ('' = not given: info)
    host:=''                 device host name or IP address; '' = the params file's
    port:=''                 device TCP port; '' = the params file's

Its device is its simulator: run `ros2 run virtual_gimbal_driver virtual_gimbal_sim --port 4950`
first, or pass sim:=true.
Uses launch/launch_ros, which a full ROS 2 install provides (not the pip environment).
"""

from gimbal_driver_common.ros.description_launch import driver_launch_description


def generate_launch_description():
    return driver_launch_description('virtual_gimbal_driver')
