"""Report on recorded runs: a verdict on each index, what the run was, its live
parameter changes, and figures.

    python scripts/analyze.py BAG [BAG ...] [TUNING_DIR ...] --out DIR [--map role=/topic]

BAG is a rosbag2 directory or a lone .mcap file, the stack's own or anyone's with
standard message types; several bags overlay on each figure (with their differences
in report.html). Each run is judged by its scenario's report.require: pass, fail, or
not judged and why (a run that ended before its stop, a partial bag). A TUNING_DIR
(the --out of tune.py) adds its convergence history. Roles for --map: target_speed,
state, measured_speed, command, controller_state, position. DIR is created, or an
existing directory whose report files are replaced.
"""

from __future__ import annotations

from pathlib import Path

from ato_nodes import cli
from ato_nodes.reports.analysis import ReportError
from ato_nodes.bags.bagio import BagError, parse_mapping, read_run
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.reports.report import write_report


def main() -> None:
    parser = cli.argument_parser(__doc__)
    parser.add_argument("inputs", nargs="+", type=Path, help="bags and tuning directories")
    parser.add_argument("--out", type=Path, required=True, help="report directory")
    parser.add_argument("--map", action="append", default=[], metavar="ROLE=/TOPIC")
    args = parser.parse_args()
    if args.out.exists() and not args.out.is_dir():
        cli.fail(f"--out {args.out} exists and is not a directory; choose another")
    try:
        mapping = parse_mapping(args.map)
        tunings = [p for p in args.inputs if (p / "history.csv").is_file()]
        runs = [read_run(p, mapping) for p in args.inputs if p not in tunings]
        md_path, html_path = write_report(runs, tunings, args.out)
    except (BagError, ScenarioError, ReportError) as exc:  # ScenarioError: report.* in a bag
        cli.fail(str(exc))
    except OSError as exc:
        cli.fail(f"--out {args.out}: cannot write the report: {exc.strerror or exc}")
    for run in runs:
        if run.partial:
            print(f"{run.path}: partial: {run.partial}; the indices cover the steps recorded")
        if run.missing:  # the roles the bag lacks (analysis.run_indices: "skipped")
            print(f"{run.path}: no {', '.join(run.missing)} topic; indices needing them skipped")
    print(f"report: {md_path} and {html_path}")
