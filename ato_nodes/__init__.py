"""ATO stack: ROS-free core (ato_nodes.core) and thin rclpy nodes (ato_nodes.nodes)."""
