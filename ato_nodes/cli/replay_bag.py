"""Replay a bag onto the ROS graph, like `ros2 bag play --clock`.

    python scripts/replay_bag.py BAG [--rate 2] [--topics /a /b] [--start 10] [--end 60]
                                 [--loop] [--domain-id N] [--wait-subscribers 1]

Every topic is republished with its recorded type, the recorded bytes, in recorded
order and pacing (scaled by --rate; --rate 0 = as fast as possible). /clock comes
from the recorded time: replayed as recorded when the bag has it, else published
before each new stamp. Publishers are reliable and keep-all, like the stack's.
Without --domain-id the environment's ROS_DOMAIN_ID is used, as ros2 does.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

from ato_nodes import cli
from ato_nodes.bags.bagio import BagError, read_messages
from ato_nodes.launcher.launch import DomainLock, isolate_to_this_host
from ato_nodes.nodes import watchdog

WAIT_LIMIT = 30.0  # s to wait for --wait-subscribers


def parse_args() -> argparse.Namespace:
    parser = cli.argument_parser(__doc__)
    parser.add_argument("bag", type=Path)
    parser.add_argument("--rate", type=float, default=1.0, help="speed factor; 0 = no pacing")
    parser.add_argument("--topics", nargs="+", help="only these topics")
    parser.add_argument("--start", type=float, default=0.0, help="offset from the bag start, s")
    parser.add_argument("--end", type=float, help="offset from the bag start to stop at, s")
    parser.add_argument("--loop", action="store_true", help="play again and again until Ctrl-C")
    parser.add_argument("--domain-id", type=int, help="ROS domain (default: $ROS_DOMAIN_ID)")
    parser.add_argument("--wait-subscribers", type=int, default=0, metavar="N",
                        help=f"wait (up to {WAIT_LIMIT:g} s) until every topic has N subscribers")
    parser.add_argument("--quiet", action="store_true")
    return parser.parse_args()


def main() -> None:
    args = parse_args()
    check_window(args)
    _held = claim_domain(args.domain_id)  # released when the process exits
    types, messages = messages_to_replay(args)

    import rclpy

    rclpy.init()
    node = rclpy.create_node("bag_replay")
    try:
        replay(node, args, types, messages)
    except KeyboardInterrupt:
        pass
    finally:
        # Every message is out (and acknowledged); the DDS teardown once hung for minutes
        # after a slow reliable subscriber on a loaded machine: it may not hold the exit.
        leaving = sys.exc_info()[1]  # the exit under way, if any: its status stands
        status = leaving.code if isinstance(leaving, SystemExit) else int(leaving is not None)
        watchdog.exit_after(watchdog.TEARDOWN_LIMIT, status)
        node.destroy_node()
        rclpy.try_shutdown()


def check_window(args: argparse.Namespace) -> None:
    """--rate, --start and --end as numbers a replay can use, else fail."""
    finite = all(math.isfinite(x) and abs(x) < 1e9 for x in (
        args.rate, args.start, args.end if args.end is not None else 0.0))
    if not finite or args.rate < 0 or args.start < 0 or (
            args.end is not None and args.end <= args.start):
        cli.fail("--rate and --start must be finite and not negative, and --end must exceed "
                 "--start (seconds, below 1e9)")


def claim_domain(requested: int | None) -> DomainLock:
    """The ROS domain to replay into (--domain-id, else $ROS_DOMAIN_ID), set in this
    process's environment and locked; the lock lasts as long as the returned object."""
    domain = requested if requested is not None else int(
        os.environ.get("ROS_DOMAIN_ID", "0") or 0)
    if not 0 <= domain <= 232:
        cli.fail(f"ROS domain {domain} is outside 0-232")
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    isolate_to_this_host(os.environ)
    try:  # a run's domain is its own: never replay into it
        return DomainLock(domain)
    except RuntimeError:
        cli.fail(f"ROS domain {domain} is in use by a run of this project; replay into "
                 "another --domain-id")


def messages_to_replay(args: argparse.Namespace) -> tuple[dict[str, str], list]:
    """(topic -> type, the bag's messages between --start and --end), else fail."""
    try:
        types, messages = read_messages(args.bag, args.topics)
    except BagError as exc:
        cli.fail(str(exc))
    if not messages:
        cli.fail(f"{args.bag}: no messages to replay")
    first = messages[0][1]
    begin = first + round(args.start * 1e9)
    end = first + round(args.end * 1e9) if args.end is not None else None
    messages = [m for m in messages if m[1] >= begin and (end is None or m[1] <= end)]
    if not messages:
        cli.fail(f"{args.bag}: no messages between --start and --end")
    return types, messages


def replay(node, args: argparse.Namespace, types: dict[str, str], messages: list) -> None:
    """Publish the messages (again and again with --loop), wait for their
    acknowledgement, and say how fast it went."""
    import rclpy
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock

    from ato_nodes.nodes.base import QOS

    publishers = create_publishers(node, types, args.bag)
    clock = None if "/clock" in types else node.create_publisher(Clock, "/clock", QOS["data"])
    wait_for_subscribers(publishers, args.wait_subscribers)
    played, started = 0, time.monotonic()
    while True:
        played += play(messages, publishers, clock, args.rate, Clock, Time)
        if not args.loop:
            break
    unacknowledged = [topic for topic, publisher in publishers.items()
                      if not publisher.wait_for_all_acked(rclpy.duration.Duration(seconds=10))]
    if unacknowledged:
        print(f"warning: subscribers of {', '.join(unacknowledged)} did not acknowledge "
              "every message within 10 s", file=sys.stderr)
    if not args.quiet:
        elapsed = time.monotonic() - started
        print(f"replayed {played} messages in {elapsed:.3f} s "
              f"({played / max(elapsed, 1e-9):,.0f} messages/s)", file=sys.stderr)


def create_publishers(node, types: dict[str, str], bag: Path) -> dict:
    """topic -> a publisher of its recorded type, else fail naming the type missing."""
    from ato_nodes.nodes.base import QOS, message_class

    publishers = {}
    for topic, type_name in types.items():
        try:
            publishers[topic] = node.create_publisher(message_class(type_name), topic,
                                                      QOS["data"])
        except (ImportError, AttributeError, ValueError):
            cli.fail(f"{bag}: message type {type_name} of {topic} is not installed")
    return publishers


def wait_for_subscribers(publishers, count: int) -> None:
    deadline = time.monotonic() + WAIT_LIMIT
    while count and any(p.get_subscription_count() < count for p in publishers.values()):
        if time.monotonic() > deadline:
            cli.fail(f"fewer than {count} subscribers after {WAIT_LIMIT:g} s")
        time.sleep(0.01)


def play(messages, publishers, clock, rate, Clock, Time) -> int:
    """Publish every message at its recorded offset / rate; returns how many."""
    started = time.monotonic()
    first = messages[0][1]
    last_stamp = None
    for topic, stamp, raw in messages:
        if rate > 0:
            delay = started + (stamp - first) * 1e-9 / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        if clock is not None and stamp != last_stamp:
            clock.publish(Clock(clock=Time(sec=stamp // 1_000_000_000,
                                           nanosec=stamp % 1_000_000_000)))
            last_stamp = stamp
        publishers[topic].publish(raw)
    return len(messages)
