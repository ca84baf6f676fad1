"""Score a recorded run from its bag alone: ITAE, IAE, ISE, max |e|, seed 004's J, and
the operation indices of a line (energy, jerk, switches, overspeed, stop, run time).

    python scripts/score_bag.py BAG [--json] [--map role=/topic] [--resimulate]

BAG is a rosbag2 directory or a lone .mcap file. A partial bag (a run interrupted,
timed out or diverged before its planned steps) is scored over the steps it holds and
said so ("partial: interrupted at step 99 of 2000"; in --json, "partial"); a journey
that ended at its last stop (run.last_stop_hold) is complete, and said so; a run that
ended short of its stop, still moving, is said so too: its stopping and running-time
errors judge nothing. A journey's results are also given per station (stop error,
arrival and departure lateness, dwell, verdict) and per section, and its stopping error
and arrival time are its last stop's: none (null, "not reached") if the train did not
stop there. A bag with no message is one line, exit 2.
"""

from __future__ import annotations

import sys

from ato_nodes.results import jsontext
from ato_nodes import cli
from ato_nodes.bags.bagio import BagError, ExternalLaw, parse_mapping, read_run, resimulate
from ato_nodes.core.scoring.catalogue import format_indices
from ato_nodes.core.run.last_stop import AT_LAST_STOP
from ato_nodes.core.run.scoring import stop_not_reached
from ato_nodes.core.scoring.journey import last_stop_missed
from ato_nodes.results.journeys import score_run


def main() -> None:
    parser = cli.argument_parser(__doc__)
    parser.add_argument("bag", help="rosbag2 directory (metadata.yaml + .mcap)")
    parser.add_argument("--json", action="store_true", help="print the indices as JSON")
    parser.add_argument("--map", action="append", default=[], metavar="ROLE=/TOPIC",
                        help="read a role from another topic (see analyze.py --help)")
    parser.add_argument("--resimulate", action="store_true",
                        help="also run the same run in-process from the bag alone (its "
                        "parameters, kept files and live gain changes) and check that every "
                        "recorded series is reproduced bit for bit (exit 1 if not)")
    args = parser.parse_args()
    try:
        run = read_run(args.bag, parse_mapping(args.map))
        differ = resimulate(run)[1] if args.resimulate else []
    except ExternalLaw as exc:  # scored as it is, the reason said once
        print(exc, file=sys.stderr)
        args.resimulate, differ = False, []
    except BagError as exc:
        cli.fail(str(exc))
    indices = score_run(run.series, run.parameters)
    if run.partial:
        indices["partial"] = run.partial
    if args.resimulate:
        indices["resimulated_identical"] = not differ
    if args.json:
        print(jsontext.dumps(indices, indent=2))
    else:
        if run.partial:
            print(f"partial: {run.partial}; the indices cover the steps recorded")
        elif run.ended_at_last_stop:
            print(f"complete: ended {AT_LAST_STOP} after {run.recorded_steps} steps "
                  f"(run.last_stop_hold {run.parameters['run.last_stop_hold']:g} s)")
        print(format_indices(indices))
        short = last_stop_missed(indices["journey"]) if "journey" in indices \
            else stop_not_reached(run.series, run.parameters)
        if short:
            print(f"not at the stop: {short}; its stopping and running-time errors are not judged")
    if args.resimulate and not args.json:
        changes = sum(len(c) for c in run.parameter_changes.values())
        print(f"re-simulated in-process from the bag ({changes} live parameter change(s)): "
              + ("every recorded series identical, bit for bit" if not differ else
                 "differs in " + ", ".join(differ)))
    if differ:
        sys.exit(1)
