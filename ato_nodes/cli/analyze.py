"""Report on recorded runs: a verdict on each index, what the run was, and figures.

    python scripts/analyze.py BAG [BAG ...] [TUNING_DIR ...] --out DIR [--map role=/topic]

BAG is a rosbag2 directory or a lone .mcap file, the stack's own or anyone's with
standard message types; several bags overlay on each figure (with their differences
in report.html). Each run is judged by its scenario's report.require. A TUNING_DIR (the
--out of tune.py) adds its convergence history. Roles for --map: target_speed,
state, measured_speed, command, controller_state, position.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ato_nodes import cli
from ato_nodes.analysis import write_report
from ato_nodes.bagio import BagError, parse_mapping, read_run
from ato_nodes.core.errors import ScenarioError


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="\n".join(__doc__.splitlines()[2:]))
    parser.add_argument("inputs", nargs="+", type=Path, help="bags and tuning directories")
    parser.add_argument("--out", type=Path, required=True, help="report directory")
    parser.add_argument("--map", action="append", default=[], metavar="ROLE=/TOPIC")
    args = parser.parse_args()
    try:
        mapping = parse_mapping(args.map)
        tunings = [p for p in args.inputs if (p / "history.csv").is_file()]
        runs = [read_run(p, mapping) for p in args.inputs if p not in tunings]
    except BagError as exc:
        cli.fail(str(exc))
    try:
        md_path, html_path = write_report(runs, tunings, args.out)
    except ScenarioError as exc:  # a bag's report.* parameters
        cli.fail(str(exc))
    for run in runs:
        if run.missing:  # the roles the bag lacks (analysis.run_indices: "skipped")
            print(f"{run.path}: no {', '.join(run.missing)} topic; indices needing them skipped")
    print(f"report: {md_path} and {html_path}")
