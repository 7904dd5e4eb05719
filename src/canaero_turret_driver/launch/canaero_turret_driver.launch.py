"""Launch the CANaerospace turret driver as a managed (lifecycle) node.

ros2 launch canaero_turret_driver canaero_turret_driver.launch.py [params_file:=...]
    [autostart:=true] [namespace:=...]
With autostart false (the default here) a lifecycle manager configures and activates it.
Bring the CAN interface up first (see the package README), e.g.
    sudo ip link set can0 type can bitrate 500000 && sudo ip link set can0 up
use_description:=true also starts robot_state_publisher with urdf/canaero_turret_driver.urdf
(or description_file:=...), which the node uses for ~/look_at too.
sim:=true also starts canaero_turret_sim (slcan on /tmp/canaero_turret,
config/canaero_turret_driver_sim.yaml).
Uses launch/launch_ros, which a full ROS 2 install provides (not the pip environment).
"""

from gimbal_driver_common.ros.description_launch import driver_launch_description


def generate_launch_description():
    return driver_launch_description('canaero_turret_driver')
