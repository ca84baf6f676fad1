"""Subscribes (reliable, keep all) to the given topics and, once nothing has arrived
for IDLE seconds after the first message, prints every message received as JSON:
{topic: [hex of the CDR bytes, ...]} in arrival order.

    ROS_DOMAIN_ID=N python tests/capture_probe.py IDLE TOPIC:TYPE [TOPIC:TYPE ...]
"""

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rclpy  # noqa: E402

from ato_nodes.nodes.base import QOS, message_class  # noqa: E402


def main() -> None:
    idle = float(sys.argv[1])
    rclpy.init()
    node = rclpy.create_node("capture_probe")
    received = {}
    last = [None]

    def keep(topic):
        def callback(data: bytes) -> None:
            received[topic].append(data.hex())
            last[0] = time.monotonic()
        return callback

    for item in sys.argv[2:]:
        topic, type_name = item.split(":")
        received[topic] = []
        node.create_subscription(message_class(type_name), topic, keep(topic), QOS["data"],
                                 raw=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (last[0] is None or time.monotonic() - last[0] < idle):
        rclpy.spin_once(node, timeout_sec=0.05)
    print(json.dumps(received))
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
