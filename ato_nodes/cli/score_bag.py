"""Score a recorded run from its bag alone: ITAE, IAE, ISE, max |e|, seed 004's J.

    python scripts/score_bag.py BAG [--json] [--map role=/topic]

BAG is a rosbag2 directory or a lone .mcap file.
"""

from __future__ import annotations

import argparse
import json

from ato_nodes import cli
from ato_nodes.bagio import BagError, parse_mapping, read_run
from ato_nodes.core.scoring import format_indices, score_series


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag", help="rosbag2 directory (metadata.yaml + .mcap)")
    parser.add_argument("--json", action="store_true", help="print the indices as JSON")
    parser.add_argument("--map", action="append", default=[], metavar="ROLE=/TOPIC",
                        help="read a role from another topic (see analyze.py --help)")
    args = parser.parse_args()
    try:
        run = read_run(args.bag, parse_mapping(args.map))
    except BagError as exc:
        cli.fail(str(exc))
    indices = score_series(run.series, run.parameters)
    print(json.dumps(indices, indent=2) if args.json else format_indices(indices))
