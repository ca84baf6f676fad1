"""Thin rclpy wrappers, one process each, over the ROS-free core."""
