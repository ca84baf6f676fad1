"""Run the ATO stack: every node in its own process, lockstep on simulated time,
recorded to a rosbag2 MCAP bag, scored at the end.

    python scripts/run_stack.py                       # seed 000, paper-faithful
    python scripts/run_stack.py --scenario seed000-step --set adrc.r0=20
    python scripts/run_stack.py --scenario stgallen-wil-journey --journey FILE_OR_ID
    python scripts/run_stack.py --external controller -- python my_controller.py
    python scripts/run_stack.py --external controller    # prints where; you start it

With --external ROLE a node of your own stands in for the controller or the profile
(docs/external-nodes.md): COMMAND, after --, is started in the run's ROS domain and
environment with `--ros-args -r __node:=ROLE -p use_sim_time:=true --params-file FILE`
appended (FILE the run's ROS parameter file); without a COMMAND the domain and the
arguments are printed and the run waits supervisor.ready_timeout for your node.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from ato_nodes import cli
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import check_launcher_free, prepare
from ato_nodes.core.config.schema import steps
from ato_nodes.core.run.last_stop import AT_LAST_STOP
from ato_nodes.core.scoring.catalogue import format_indices
from ato_nodes.core.targets.timetable import journey_file
from ato_nodes.bags.summary import bag_contents, write_summary

EXIT_FAILED, EXIT_INTERRUPTED = 1, 130


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The options; `command` what follows the first `--` (an external node's command)."""
    from ato_nodes.launcher.launch import split_command
    ours, command = split_command(sys.argv[1:] if argv is None else argv)
    parser = cli.argument_parser(__doc__)
    parser.add_argument("--scenario", default="seed000",
                        help="scenario name in msg_config/scenarios or a YAML file "
                             "(default seed000)")
    parser.add_argument("--duration", type=float, help="simulated seconds (overrides run.duration)")
    parser.add_argument("--journey", metavar="FILE_OR_ID",
                        help="drive this TTOBench journey (its .json file, or the id of one in "
                             "msg_config/ttobench/journeys/) as the scenario's journey: sets "
                             "profile.journey.timetable")
    parser.add_argument("--out", type=Path,
                        help="bag directory to create (default bags/<scenario>-<time>)")
    parser.add_argument("--real-time", action="store_true", help="pace the clock at wall speed")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a parameter, e.g. --set adrc.mu1=7000 (repeatable)")
    parser.add_argument("--domain-id", type=int, help="ROS domain id (default: a free one, 1-101)")
    parser.add_argument("--timeout", type=float, help="give up after this many wall seconds")
    parser.add_argument("--quiet", action="store_true", help="no node output, no progress")
    parser.add_argument("--external", metavar="ROLE",
                        help="a node of your own stands in for ROLE (controller or profile): "
                             "the command after --, or one you start")
    args = parser.parse_args(ours)
    args.command = command
    return args


def external_nodes(args: argparse.Namespace) -> dict[str, list[str]]:
    """--external and its command, checked before anything starts (one line, exit 2)."""
    from ato_nodes.launcher.launch import external_nodes as checked
    try:
        return checked(args.external, args.command)
    except ScenarioError as exc:
        cli.fail(str(exc))


def main() -> None:
    cli.interrupted_quietly(run_stack)


def run_stack() -> None:
    args = parse_args()
    values = checked_values(args)
    external = external_nodes(args)
    name = Path(args.scenario).stem
    bag = args.out or Path("bags") / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}"
    cli.new_directory(bag)
    cli.seconds(args.timeout, "--timeout")

    from ato_nodes.launcher.launch import Stack  # imports no ROS itself; kept lazy for speed
    try:
        stack = Stack(values, bag, domain_id=args.domain_id, quiet=args.quiet,
                      timeout=args.timeout, external=external)
    except RuntimeError as exc:
        cli.fail(str(exc))
    # From here a stop is the run's: noted and handled by stack.run(), which decides the
    # outcome; one that comes after it (while the bag is scored) changes nothing.
    for number in cli.STOP_SIGNALS:
        signal.signal(number, stack.interrupt)
    at_most = "at most " if values["run.last_stop_hold"] > 0 else ""  # it may end at its stop
    print(f"scenario {name}: {at_most}{steps(values)} steps of {values['run.period']:g} s, "
          f"ROS_DOMAIN_ID={stack.lock.domain_id}, bag {bag}", file=sys.stderr)
    outcome = stack.run()
    summary = summarized(name, bag, outcome, stack.params_yaml)  # the console says it
    recorded = f"{summary.get('scored_steps', 0)} steps recorded in {bag}"
    if summary["status"] == "interrupted":  # the message after what every interrupt says
        details = summary["message"].split("; ", 1)[1:]
        print("; ".join(["interrupted", recorded, *details]), file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    if summary["status"] != "completed":
        print(f"error: {summary['message']}; {recorded}", file=sys.stderr)
        sys.exit(EXIT_FAILED)
    print(format_indices(summary["indices"]))
    if outcome.report.get("ended") == AT_LAST_STOP:
        print(f"ended {AT_LAST_STOP} after {outcome.report['steps']} of at most "
              f"{steps(values)} steps")
    print(f"real-time factor {outcome.report['real_time_factor']:.1f} "
          f"({outcome.report['steps_per_second']:.0f} steps/s, "
          f"loop {outcome.report['loop_wall_time']:.2f} s, "
          f"total {outcome.wall_time:.2f} s wall)")
    print(f"bag: {bag}  summary: {bag / 'summary.json'}")


def checked_values(args: argparse.Namespace) -> dict:
    """The run's values from the options, checked; a problem is one line and exit 2."""
    try:
        overrides = list(args.set)
        if args.duration is not None:
            overrides.append(f"run.duration={args.duration}")
        if args.real_time:
            overrides.append("run.real_time=true")
        if args.journey is None:
            values = prepare(args.scenario, overrides)
        else:
            values = journey_values(args.scenario, overrides, args.journey)
        check_launcher_free(values)
    except ScenarioError as exc:
        cli.fail(str(exc))
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        cli.fail(f"--domain-id {args.domain_id} is outside 0-232")
    return values


def journey_values(scenario: str, overrides: list[str], journey: str) -> dict:
    """prepare() with --journey's timetable as profile.journey.timetable; a scenario
    that is not a journey (its profile.kind, after the --set overrides) refused naming
    --journey, which the user gave, not the parameter it sets."""
    timetable = f"profile.journey.timetable={journey_file(journey)}"
    try:
        return prepare(scenario, [*overrides, timetable])
    except ScenarioError as refused:
        try:  # the run's kind, to say why (a journey kind may need --journey's timetable)
            kind = prepare(scenario, overrides)["profile.kind"]
        except ScenarioError:
            raise refused from None
        if kind != "journey":
            raise ScenarioError(f"--journey {journey}: scenario {scenario} is not a journey "
                                f"(its profile.kind is {kind}): --journey gives the timetable "
                                "of a journey scenario, e.g. --scenario "
                                "stgallen-wil-journey") from None
        raise


def summarized(name: str, bag: Path, outcome, params_yaml: str) -> dict:
    """summary.json's contents, written into the bag with params.yaml when there is a
    bag; what could not be written is said in its message. Its status is the run's
    outcome, as the console and the exit status say it: a run that completed but whose
    bag cannot be scored has failed."""
    summary = {"scenario": name, "bag": str(bag), "status": outcome.status,
               "message": outcome.message, "domain_id": outcome.domain_id,
               "wall_time": outcome.wall_time, **outcome.report}
    if bag.exists():
        summary.update(bag_contents(bag))
    said = [summary["message"]]
    if "bag_error" in summary:
        said.append(f"bag not scored: {summary['bag_error']}")
    if outcome.ok and "indices" not in summary:  # said as a failure everywhere
        summary["status"] = "failed"
        if "bag_error" not in summary:
            said.append("the run completed without a scored step")
    summary["message"] = "; ".join(filter(None, said))
    if bag.exists():
        try:
            (bag / "params.yaml").write_text(params_yaml)
        except OSError as exc:
            summary["message"] += f"; params.yaml not written: {exc.strerror or exc}"
        summary["message"] = "; ".join(filter(None, [summary["message"],
                                                     write_summary(bag, summary)]))
    return summary
