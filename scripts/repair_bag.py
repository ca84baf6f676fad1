#!/usr/bin/env python3
"""Make a bag whose recorder died (SIGKILL, power loss, a full disk) complete again.

    python scripts/repair_bag.py BAG [BAG ...]

Keeps every message up to the first incomplete record (a killed recorder loses at
most the last second of simulated time) and writes metadata.yaml; a complete bag
is left as it is. The launcher does this by itself after every run. A directory
that is not an MCAP bag (no .mcap file in it) is said so, exit 2.
"""

from __future__ import annotations

from pathlib import Path

import _cli

from ato_nodes.bags.bagrepair import RepairError, repair


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("bags", nargs="+", type=Path, help="rosbag2 directories")
    args = parser.parse_args()
    for bag in args.bags:
        if not bag.is_dir():
            _cli.fail(f"{bag} is not a bag directory")
        try:
            print(repair(bag).describe())
        except RepairError as exc:
            _cli.fail(str(exc))


if __name__ == "__main__":
    main()
