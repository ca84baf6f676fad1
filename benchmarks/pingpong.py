"""Two-process rclpy ping-pong, the reference the benchmark compares the stack to.

    python benchmarks/pingpong.py echo            # answers every /ping on /pong
    python benchmarks/pingpong.py ping N          # sends N pings, prints round trips/s

benchmark.py starts both, in the environment of the stack's nodes.

Plain rclpy: a SingleThreadedExecutor, std_msgs/Float64, the stack's data QoS.
"""

from __future__ import annotations

import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import Float64

from ato_nodes.nodes.base import QOS

SETTLE = 0.3  # s after matching before timing, so discovery traffic has calmed


def main() -> None:
    role = sys.argv[1]
    count = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    rclpy.init()
    node = Node(f"pingpong_{role}")
    outgoing = node.create_publisher(Float64, "/ping" if role == "ping" else "/pong", QOS["data"])
    state = {"received": 0, "start": 0.0}

    def on_message(msg: Float64) -> None:
        if role == "echo":
            outgoing.publish(msg)
            return
        state["received"] += 1
        if state["received"] >= count:
            elapsed = time.perf_counter() - state["start"]
            print(f"{count / elapsed:.1f}", flush=True)
            rclpy.try_shutdown()
            return
        outgoing.publish(msg)

    incoming = node.create_subscription(Float64, "/pong" if role == "ping" else "/ping",
                                        on_message, QOS["data"])
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        if role == "ping":
            while outgoing.get_subscription_count() < 1 or incoming.get_publisher_count() < 1:
                executor.spin_once(timeout_sec=0.01)
            time.sleep(SETTLE)
            state["start"] = time.perf_counter()
            outgoing.publish(Float64(data=0.0))
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
