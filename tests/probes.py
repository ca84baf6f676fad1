"""What the probe scripts (run as child processes of the tests) share."""

import json
import os
import sys
import threading
import time
from pathlib import Path

import rclpy

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ato_nodes.launcher.launch import DomainLock  # noqa: E402

LOCK_POLL = 0.05  # s between checks that the probe's domain is still held
taken_over: list[DomainLock] = []  # the domain's lock once its holder let go: kept till exit


def init_in_held_domain() -> None:
    """rclpy.init() in $ROS_DOMAIN_ID, which must be held through the project's DomainLock
    (by the test, or by the run the probe watches): a probe in a domain nobody holds
    could mix with another suite's run there, so it refuses (exit 2). Should the holder
    let go while the probe is still in the domain, the probe takes the lock itself and
    keeps it until it exits."""
    domain_id = int(os.environ.get("ROS_DOMAIN_ID", "0"))
    try:
        free = DomainLock(domain_id)
    except RuntimeError:  # held: what a probe needs
        pass
    else:
        free.release()
        print(f"error: ROS domain {domain_id} is held by no DomainLock; a probe runs only in "
              "a domain a test or a run holds", file=sys.stderr)
        sys.exit(2)

    def keep_held() -> None:
        while True:
            try:
                taken_over.append(DomainLock(domain_id))  # free now: the probe's
                return
            except RuntimeError:
                time.sleep(LOCK_POLL)

    threading.Thread(target=keep_held, name="domain-lock", daemon=True).start()
    rclpy.init()


def spin_then_print(node, seconds: float, done, result) -> None:
    """Spin `node` until done() or `seconds` have passed, print `result` as JSON (the
    test reads it from stdout), then tear ROS down."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not done():
        rclpy.spin_once(node, timeout_sec=0.05)
    print(json.dumps(result))
    node.destroy_node()
    rclpy.try_shutdown()
