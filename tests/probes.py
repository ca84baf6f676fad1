"""What the probe scripts (run as child processes of the tests) share."""

import json
import time

import rclpy


def spin_then_print(node, seconds: float, done, result) -> None:
    """Spin `node` until done() or `seconds` have passed, print `result` as JSON (the
    test reads it from stdout), then tear ROS down."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not done():
        rclpy.spin_once(node, timeout_sec=0.05)
    print(json.dumps(result))
    node.destroy_node()
    rclpy.try_shutdown()
