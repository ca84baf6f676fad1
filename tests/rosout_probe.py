"""Stands in for `ros2 topic echo /rosout`: prints, as JSON, the log lines the run's
nodes sent ({node: [message, ...]}), once every node named on the command line has
logged its end of run (or after SECONDS).

    ROS_DOMAIN_ID=N python tests/rosout_probe.py SECONDS NODE [NODE ...]
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rcl_interfaces.msg import Log  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

from probes import init_in_held_domain, spin_then_print  # noqa: E402

LAST_LINE = "run event: shutdown"


def main() -> None:
    seconds, nodes = float(sys.argv[1]), sys.argv[2:]
    init_in_held_domain()
    node = Node("rosout_probe")
    lines: dict[str, list[str]] = {name: [] for name in nodes}
    # what `ros2 topic echo` chooses against /rosout's publishers: reliable, transient local
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(Log, "/rosout",
                             lambda msg: lines.setdefault(msg.name, []).append(msg.msg), qos)
    spin_then_print(node, seconds,
                    lambda: all(any(line.startswith(LAST_LINE) for line in lines[name])
                                for name in nodes), lines)


if __name__ == "__main__":
    main()
