"""rclpy side of the shared driver infrastructure (the only part that imports ROS)."""
