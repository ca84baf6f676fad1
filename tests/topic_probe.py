"""Stands in for `ros2 topic echo TOPIC` (no ros2 CLI wheel exists): prints 'ready' once
subscribed, then what arrived, as a JSON list, once nothing has for QUIET seconds
(default 1; or after SECONDS): the values of a topic of the topic map (std_msgs/Float64:
`data`), or the log records of /rosout ({"name", "level", "msg"}).

    ROS_DOMAIN_ID=N python tests/topic_probe.py /ato/running_fitness SECONDS
    ROS_DOMAIN_ID=N python tests/topic_probe.py /rosout SECONDS QUIET
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rclpy  # noqa: E402
from rcl_interfaces.msg import Log  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

from ato_nodes.core.base.topics import topic_map  # noqa: E402
from ato_nodes.nodes.base import QOS, message_class  # noqa: E402
from probes import init_in_held_domain, spin_then_print  # noqa: E402

ROSOUT_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)


def main() -> None:
    name, seconds = sys.argv[1], float(sys.argv[2])
    quiet = float(sys.argv[3]) if len(sys.argv) > 3 else 1.0
    init_in_held_domain()
    node = rclpy.create_node("topic_probe")
    received, last = [], [time.monotonic()]
    if name == "/rosout":
        kind, qos = Log, ROSOUT_QOS
        pick = lambda msg: {"name": msg.name, "level": msg.level, "msg": msg.msg}  # noqa: E731
    else:
        topic = next(t for t in topic_map().values() if t.name == name)
        kind, qos, pick = message_class(topic.type), QOS[topic.qos], lambda msg: msg.data

    def arrived(msg) -> None:
        received.append(pick(msg))
        last[0] = time.monotonic()

    node.create_subscription(kind, name, arrived, qos)
    print("ready", flush=True)
    spin_then_print(node, seconds, lambda: received and time.monotonic() - last[0] > quiet,
                    received)


if __name__ == "__main__":
    main()
