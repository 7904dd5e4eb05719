"""Capture Systems pan-tilt pedestal driver: protocol codec, client, simulator, ROS node."""
