#!/usr/bin/env python3
"""A delay on a journey and what re-planning wins back: the journey run on time, then with
a dwell extended (--delay: profile.journey.dwell_extension STOP:SECONDS) or a temporary
speed restriction (--restriction: profile.journey.speed_restriction START:END:SPEED), or
both, twice, keeping its on-time curves (profile.journey.catch_up 0) and catching up (the
scenario's catch-up curves), side by side, in-process: per station the arrival lateness
and the stop, the journey's traction energy, and the re-plans the profile made.

    python scripts/journey_delay.py seed004-metro-line --delay 2:30
    python scripts/journey_delay.py seed004-metro-line --restriction 4000:4600:8.33
    python scripts/journey_delay.py seed004-metro-line --delay 2:30 --out bags/delay-metro
    python scripts/journey_delay.py seed004-metro-line --delay 2:30 \
        --set profile.journey.catch_up_share=1 --set profile.journey.catch_up_braking=1.23

Prints the table; with --out, writes delay.md and delay.json there.
"""

from __future__ import annotations

from pathlib import Path

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.scoring.journey import STOPPED
from ato_nodes.core.targets.served import replans
from ato_nodes.results.journeys import run_journey, run_timetable
from ato_nodes.studies.runner import write_outputs

ON_TIME, KEPT, CAUGHT_UP = "on time", "delayed, on-time curves kept", "delayed, catching up"


def variants(delay: str | None, restriction: str | None) -> dict[str, list[str]]:
    faults = [f"profile.journey.{name}={value}" for name, value in
              (("dwell_extension", delay), ("speed_restriction", restriction)) if value]
    return {ON_TIME: [], KEPT: [*faults, "profile.journey.catch_up=0"], CAUGHT_UP: faults}


def journey_run(values: dict) -> dict:
    """The run's stations (arrival lateness s, stop error m), traction energy and re-plans."""
    series = simulate(values)
    indices = run_journey(series, values, run_timetable(values))
    made = replans(RunContext(values).plan, values["run.period"], series["position"])
    return {"stations": {station.station: {"outcome": station.outcome,
                                           "arrival_lateness_s": station.arrival_lateness,
                                           "stop_error_m": station.stop_error}
                         for station in indices.stations[1:]},
            "traction_energy_kwh": indices.traction_energy_kwh,
            "replans": [replan.text() for replan in made]}


def station_cell(cell: dict) -> str:
    if cell["outcome"] != STOPPED:  # passed, or not reached before the run's end
        return cell["outcome"]
    return f"{cell['arrival_lateness_s']:+.1f}, {cell['stop_error_m']:+.3f}"


def table(runs: dict[str, dict]) -> str:
    """Stations as rows, each run's arrival lateness (s) and stop (m) as columns."""
    labels = list(runs)
    lines = ["| station | " + " | ".join(f"{label}: arrival s, stop m" for label in labels)
             + " |", "|---|" + "---|" * len(labels)]
    for station in runs[labels[0]]["stations"]:
        cells = [runs[label]["stations"][station] for label in labels]
        lines.append(f"| {station} | " + " | ".join(map(station_cell, cells)) + " |")
    lines.append("| traction energy kWh | " + " | ".join(
        f"{runs[label]['traction_energy_kwh']:.2f}" for label in labels) + " |")
    said = [f"- {text}" for text in runs[CAUGHT_UP]["replans"]]
    return "\n".join([*lines, "", "Re-plans (catching up):", *said])


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenario", help="a journey scenario (profile.kind journey)")
    parser.add_argument("--delay", metavar="STOP:SECONDS",
                        help="the dwell extension (profile.journey.dwell_extension)")
    parser.add_argument("--restriction", metavar="START:END:SPEED",
                        help="the temporary speed restriction, m and m/s "
                        "(profile.journey.speed_restriction)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a parameter in every run (repeatable)")
    parser.add_argument("--out", type=Path, help="directory to create for delay.md/.json")
    args = parser.parse_args()
    if not (args.delay or args.restriction):
        _cli.fail("give the delay: --delay STOP:SECONDS, --restriction START:END:SPEED or both")
    try:
        on_time = prepare(args.scenario, args.set)  # a journey before the journey's overrides
        if run_timetable(on_time) is None:
            raise ScenarioError(f"{args.scenario} is not a journey (profile.kind journey)")
        faulted = variants(args.delay, args.restriction)
        prepared = {label: prepare(args.scenario, [*args.set, *overrides]) if overrides
                    else on_time for label, overrides in faulted.items()}
    except ScenarioError as exc:
        _cli.fail(str(exc))
    if args.out is not None:
        _cli.new_directory(args.out)
    runs = {label: journey_run(values) for label, values in prepared.items()}
    markdown = table(runs)
    if args.out is not None:
        write_outputs(args.out, "delay", markdown=markdown, report=runs)
    print(markdown)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
