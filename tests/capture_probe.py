"""Subscribes (reliable, keep all) to the given topics and, once each topic has delivered
its expected COUNT of messages (or after TIMEOUT seconds), prints every message received as
JSON: {topic: [hex of the CDR bytes, ...]} in arrival order.

Stopping on counts, not on an idle gap: a reliable sample lost by the transport at the very
end of a burst is only repaired at the writer's next heartbeat (Fast DDS: up to 3 s later).

    ROS_DOMAIN_ID=N python tests/capture_probe.py TIMEOUT TOPIC:TYPE:COUNT [...]
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rclpy  # noqa: E402

from ato_nodes.nodes.base import QOS, message_class  # noqa: E402
from probes import init_in_held_domain, spin_then_print  # noqa: E402


def main() -> None:
    timeout = float(sys.argv[1])
    init_in_held_domain()
    node = rclpy.create_node("capture_probe")
    received = {}
    expected = {}

    def keep(topic):
        def callback(data: bytes) -> None:
            received[topic].append(data.hex())
        return callback

    for item in sys.argv[2:]:
        topic, type_name, count = item.split(":")
        received[topic], expected[topic] = [], int(count)
        node.create_subscription(message_class(type_name), topic, keep(topic), QOS["data"],
                                 raw=True)
    spin_then_print(node, timeout,
                    lambda: all(len(received[t]) >= n for t, n in expected.items()), received)


if __name__ == "__main__":
    main()
