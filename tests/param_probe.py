"""Stands in for `ros2 param set NODE NAME VALUE` (no ros2 CLI wheel exists): asks a live
node to set one parameter through its standard set_parameters service and prints
{"successful": ..., "reason": ..., "names": [...]} as JSON, names being what the node
declares (`ros2 param list NODE`).

    ROS_DOMAIN_ID=N python tests/param_probe.py /controller adrc.mu1 7000.0
"""

import json
import sys

import rclpy
import yaml
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

from probes import init_in_held_domain


def main() -> None:
    node_name, name, text = sys.argv[1:4]
    init_in_held_domain()
    node = rclpy.create_node("param_probe")
    client = AsyncParameterClient(node, node_name)
    if not client.wait_for_services(timeout_sec=20.0):
        print(json.dumps({"error": f"{node_name} offers no parameter services"}))
        sys.exit(1)
    listed = client.list_parameters()
    rclpy.spin_until_future_complete(node, listed, timeout_sec=20.0)
    future = client.set_parameters([Parameter(name, value=yaml.safe_load(text))])
    rclpy.spin_until_future_complete(node, future, timeout_sec=20.0)
    result = future.result().results[0]
    print(json.dumps({"successful": result.successful, "reason": result.reason,
                      "names": sorted(listed.result().result.names)}))
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
