"""CANaerospace turret driver: protocol codec, client, simulator and ROS node."""
