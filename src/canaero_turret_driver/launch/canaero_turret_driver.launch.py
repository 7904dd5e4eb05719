"""Launch the CANaerospace turret driver as a managed (lifecycle) node.

    ros2 launch canaero_turret_driver canaero_turret_driver.launch.py [name:=value ...]

Arguments (default after :=; docs/interface.md, "Launch arguments"):
    params_file:=''          parameter YAML; '' = config/canaero_turret_driver.yaml, or
                             config/canaero_turret_driver_sim.yaml with sim:=true
    autostart:=true          the node configures and activates itself; false: a lifecycle
                             manager (or ros2 lifecycle set) does
    namespace:=''            namespace of the node and of robot_state_publisher
    use_description:=false   true: also start robot_state_publisher with the URDF (TF)
    description_file:=share/canaero_turret_driver/urdf/canaero_turret_driver.urdf
                             the URDF robot_state_publisher publishes and ~/look_at aims with
    sim:=false               true: also start canaero_turret_sim (slcan on /tmp/canaero_turret,
                             config/canaero_turret_driver_sim.yaml)
    log_level:=''            the node's --ros-args --log-level: debug, info, warn, error,
                             fatal, or logger:=level ('' = not given: info)
    can_interface:=''        python-can interface (socketcan, slcan, ...); '' = the params file's
    can_channel:=''          CAN channel (can0, or the slcan tty); '' = the params file's

Bring the CAN interface up first (see the package README), e.g.
    sudo ip link set can0 type can bitrate 500000 && sudo ip link set can0 up
Uses launch/launch_ros, which a full ROS 2 install provides (not the pip environment).
"""

from gimbal_driver_common.ros.description_launch import driver_launch_description


def generate_launch_description():
    return driver_launch_description('canaero_turret_driver')
