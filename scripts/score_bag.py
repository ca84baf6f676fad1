#!/usr/bin/env python3
"""Score a recorded run from its bag alone: ITAE, IAE, ISE, max |e|, seed 004's J.

    python scripts/score_bag.py bags/seed000-20261122-120000 [--json]
"""

from __future__ import annotations

import argparse
import json

import _cli

from ato_nodes.bagio import BagError, read_parameters, read_series
from ato_nodes.core.scoring import format_indices, score_series


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag", help="rosbag2 directory (metadata.yaml + .mcap)")
    parser.add_argument("--json", action="store_true", help="print the indices as JSON")
    args = parser.parse_args()
    try:
        indices = score_series(read_series(args.bag), read_parameters(args.bag))
    except BagError as exc:
        _cli.fail(str(exc))
    print(json.dumps(indices, indent=2) if args.json else format_indices(indices))


if __name__ == "__main__":
    main()
