"""Stands in for `ros2 topic echo` (no ros2 CLI wheel exists): subscribes to every
topic of the topic map by name and type with default QoS for a while, then prints,
as JSON, how many messages each topic delivered and over what wall time.

    ROS_DOMAIN_ID=N python tests/echo_probe.py SECONDS
"""

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rclpy  # noqa: E402
from rclpy.node import Node  # noqa: E402

from ato_nodes.core.base.topics import topic_map  # noqa: E402
from ato_nodes.nodes.base import message_class  # noqa: E402
from probes import init_in_held_domain  # noqa: E402


def main() -> None:
    seconds = float(sys.argv[1])
    init_in_held_domain()
    node = Node("echo_probe")
    arrivals = {topic.name: [] for topic in topic_map().values()}
    for topic in topic_map().values():
        node.create_subscription(message_class(topic.type), topic.name,
                                 lambda msg, name=topic.name:
                                 arrivals[name].append(time.monotonic()),
                                 10)  # default QoS: reliable, volatile, keep last 10
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    print(json.dumps({name: {"count": len(times),
                             "span": (times[-1] - times[0]) if len(times) > 1 else 0.0}
                      for name, times in arrivals.items()}))
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
