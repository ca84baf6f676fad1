#!/usr/bin/env python3
"""Speed of bag replay on this machine (prints figures; asserts nothing).

    python benchmarks/benchmark_replay.py [--bag BAG]

Records (or takes) a full 2400 s seed-000 bag, replays it at maximum rate and
reports messages per second, then replays 10 s of it at --rate 1 and --rate 2
and reports both wall times (the second should be about half the first).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _cli

from ato_nodes.bags.bagio import read_messages
from ato_nodes.launcher.launch import DomainLock

ROOT = Path(__file__).resolve().parents[1]


def replay(bag: Path, *args: str) -> tuple[float, float]:
    """(wall seconds of one replay_bag.py run, seconds it reports spending on playing)."""
    free = DomainLock()  # a domain no run holds now; replay_bag.py takes its lock itself
    domain = free.domain_id
    free.release()
    started = time.monotonic()
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "replay_bag.py"), str(bag),
                             "--domain-id", str(domain), *args], capture_output=True, text=True)
    wall = time.monotonic() - started
    if result.returncode != 0:
        _cli.fail(f"replay failed: {result.stderr.strip()}", 1)
    return wall, float(result.stderr.split(" in ")[1].split(" s ")[0])


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--bag", type=Path, help="a full seed-000 bag (default: record one)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bag = args.bag
        if bag is None:
            bag = Path(tmp) / "seed000"
            subprocess.run([sys.executable, str(ROOT / "scripts" / "run_stack.py"), "--out",
                            str(bag), "--quiet"], check=True, capture_output=True)
        count = len(read_messages(bag)[1])
        full_wall, playing = replay(bag, "--rate", "0")
        print(f"replay at maximum rate: {count} messages in {playing:.2f} s of playing = "
              f"{count / playing:,.0f} messages/s ({full_wall:.2f} s wall with start-up and "
              "reading the bag; no subscriber)")
        _, normal = replay(bag, "--rate", "1", "--end", "10")
        _, double = replay(bag, "--rate", "2", "--end", "10")
        print(f"10 s of the bag: --rate 1 plays in {normal:.2f} s, --rate 2 in {double:.2f} s "
              f"(ratio {double / normal:.3f}, expected 0.5)")


if __name__ == "__main__":
    main()
