"""Stands in for `ros2 topic echo /ato/running_fitness` (no ros2 CLI wheel exists):
prints 'ready' once subscribed, then every value received, as a JSON list, once none
has come for a second (or after SECONDS).

    ROS_DOMAIN_ID=N python tests/fitness_probe.py SECONDS
"""

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rclpy  # noqa: E402
from rclpy.node import Node  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from ato_nodes.core.topics import topic_map  # noqa: E402
from ato_nodes.nodes.base import QOS  # noqa: E402


def main() -> None:
    seconds = float(sys.argv[1])
    rclpy.init()
    node = Node("fitness_probe")
    topic = topic_map()["running_fitness"]
    values, last = [], [time.monotonic()]

    def received(msg: Float64) -> None:
        values.append(msg.data)
        last[0] = time.monotonic()

    node.create_subscription(Float64, topic.name, received, QOS[topic.qos])
    print("ready", flush=True)
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not (values and time.monotonic() - last[0] > 1.0):
        rclpy.spin_once(node, timeout_sec=0.05)
    print(json.dumps(values))
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
