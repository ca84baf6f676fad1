#!/usr/bin/env python3
"""Plan a journey's running times for least traction energy: the timetable's total
running-time supplement distributed over its sections so that every section has the same
marginal energy (core/targets/journey.py), each section then driven energy-optimally in
its time (seed 002's dynamic programme).

    python scripts/plan_journey.py metro-line
    python scripts/plan_journey.py hsr-journey --compare
    python scripts/plan_journey.py CH_StGallen_Wil_Journey_01 \
        --train ttobench/trains/CH_Stadler_KISS_SBB.json

LINE is a line file, or the name of one in msg_config/lines/ (LINE.yaml); its timetable
is --timetable, a file or the name of one in msg_config/timetables/ (default: the line's
own name there), which must be for that line. --train plans for another train
preset than the timetable's (its minimum running times are checked again). LINE may
instead be a TTOBench journey (a .json file from anywhere, or the id of one in
msg_config/ttobench/journeys/) on its associated track, for the --train given (a preset
or a TTOBench train file): its stops' windows fix each section's time (the latest
arrival, the least energy), so each section is driven in it and nothing is split;
each passing point's time on that run is said against its window. Prints per
section the minimum running time (the ato curve at the full envelope share), the
timetable's time, the allocated time and the energy of the section driven in it, and the
totals; --compare adds the uniform allocation (the supplement in proportion to the
minimum times) driven the same way and the exact optimum over every run made (a fine
grid of running-time splits). Bad input: one line, exit 2.
"""

from __future__ import annotations

from pathlib import Path

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.paths import config_dir
from ato_nodes.core.config.scenario import complete, train_preset
from ato_nodes.core.targets import journey
from ato_nodes.core.targets.timetable import (JOURNEYS, check_minimum_times, journey_file,
                                              load_timetable)


def parse_args():
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("line", metavar="LINE", help="line file, or its name in "
                        "msg_config/lines/; or a TTOBench journey, its .json file or id")
    parser.add_argument("--timetable", help="timetable file, or its name in "
                        "msg_config/timetables/ (default: LINE's name there)")
    parser.add_argument("--train", help="train preset (default: the timetable's)")
    parser.add_argument("--compare", action="store_true", help="also the uniform allocation "
                        "and the exact optimum (about twice the time)")
    return parser.parse_args()


def given_file(given: str, folder: str, what: str) -> Path:
    """The file a user gave: a path as given (with a folder or a .yaml suffix), else the
    name's file in msg_config/FOLDER/; ScenarioError naming what was given."""
    path = Path(given)
    if path.suffix in (".yaml", ".yml") or len(path.parts) > 1:
        return path
    shipped = config_dir() / folder / f"{given}.yaml"
    if not shipped.is_file():
        raise ScenarioError(f"unknown {what} {given!r}: neither a file nor a name in "
                            f"{config_dir() / folder}")
    return shipped


def is_ttobench_journey(given: str) -> bool:
    """A TTOBench journey's file (.json) or the id of a shipped one, not a line."""
    return Path(given).suffix == ".json" or (JOURNEYS / f"{given}.json").is_file()


def load_journey(args):
    """A TTOBench journey's (timetable, run values, minimum running times), for --train."""
    if args.train is None:
        raise ScenarioError(f"{args.line} is a TTOBench journey, planned for no train: give "
                            "--train (a train preset or a TTOBench train file)")
    if args.timetable is not None or args.compare:
        raise ScenarioError(f"{args.line} is a TTOBench journey: its stops' windows fix each "
                            "section's time, so there is no --timetable and nothing to "
                            "--compare")
    timetable = load_timetable(journey_file(args.line))
    values = complete({"plant.train": args.train}, [Path.cwd()])
    return timetable, values, check_minimum_times(timetable, values)


def load(args):
    """(timetable, run values, minimum running times), or one line and exit 2."""
    try:
        if is_ttobench_journey(args.line):
            return load_journey(args)
        line_file = given_file(args.line, "lines", "line")
        if not line_file.is_file():
            raise ScenarioError(f"no line file {line_file}")
        if args.timetable is None and line_file.parent != config_dir() / "lines":
            raise ScenarioError(f"line {line_file} is not one of msg_config/lines/: give its "
                                "--timetable FILE")
        timetable = load_timetable(
            given_file(args.timetable, "timetables", "timetable") if args.timetable
            else config_dir() / "timetables" / f"{line_file.stem}.yaml")
        if Path(timetable.line_file).resolve() != line_file.resolve():
            raise ScenarioError(f"timetable {timetable.path} is for line "
                                f"{timetable.line_file}, not {args.line}")
        train = args.train or timetable.train
        train_preset(train)
        values = complete({"plant.train": train}, [])
        return timetable, values, check_minimum_times(timetable, values)
    except ScenarioError as exc:
        _cli.fail(str(exc))


def main() -> None:
    args = parse_args()
    timetable, values, minimums = load(args)
    try:  # a time the programme's flat-out run cannot make
        plan = journey.plan_journey(timetable, values, minimums)
        comparison = journey.compare(plan, timetable.running_time) if args.compare else None
    except ValueError as exc:
        _cli.fail(str(exc))
    report(timetable, Path(values["plant.train"]).stem, plan, comparison)


def report(timetable, train: str, plan: journey.JourneyPlan, comparison) -> None:
    split = ("each section in its window's time" if timetable.journey
             else f"marginal energy {plan.allocation.marginal:.0f} kW")
    print(f"{timetable.line.name}, train {train}: running time {timetable.running_time:g} s "
          f"(minimum {sum(plan.minimums):.1f} s + {supplement(plan, timetable):.1f} %), "
          f"{split}")
    extra = " | uniform s | uniform kWh" if comparison else ""
    print(f"| section | km | minimum s | timetable s | allocated s | driven s | kWh{extra} |")
    print("|---|---|---|---|---|---|---|" + ("---|---|" if comparison else ""))
    for i, (section, run) in enumerate(zip(timetable.sections, plan.driven, strict=True)):
        row = (f"| {section.origin} - {section.destination} | "
               f"{(section.end - section.start) / 1000:.2f} | {plan.minimums[i]:.1f} | "
               f"{section.running_time:g} | {plan.allocation.times[i]:.1f} | "
               f"{journey.point(run, plan.sections[i])[0]:.1f} | {run.energy_kwh:.2f}")
        if comparison:
            row += (f" | {comparison.uniform_times[i]:.1f} | "
                    f"{comparison.uniform_runs[i].energy_kwh:.2f}")
        print(row + " |")
    print(f"allocation: {plan.energy_kwh:.2f} kWh")
    for line in passing_lines(timetable, plan):
        print(line)
    if comparison:
        uniform = sum(run.energy_kwh for run in comparison.uniform_runs)
        best = comparison.best_energy_kwh
        print(f"uniform: {uniform:.2f} kWh; optimum (best split): {best:.2f} kWh at "
              f"{', '.join(f'{t:.1f}' for t in comparison.best_times)} s")
        print(f"allocation {100 * (plan.energy_kwh / best - 1):+.2f} % against the optimum, "
              f"{100 * (1 - plan.energy_kwh / uniform):.2f} % saved against uniform "
              f"(uniform {100 * (uniform / best - 1):+.2f} % against the optimum)")


def passing_lines(timetable, plan: journey.JourneyPlan) -> list[str]:
    """Each passing point of a TTOBench journey: when the section's run passes it against
    its window (the journey's clock)."""
    lines = []
    for section, problem, run, stop in zip(timetable.sections, plan.sections, plan.driven,
                                           timetable.stops, strict=False):
        for point in section.passing:
            passes = stop.departure + journey.passing_time(run, problem, point.position)
            miss = point.window.miss(passes)
            lines.append(f"{point.name}: passed at {passes:.1f} s, window "
                         f"{point.window.text()}"
                         + (f": {miss:+.1f} s outside" if miss else ": inside"))
    return lines


def supplement(plan: journey.JourneyPlan, timetable) -> float:
    return 100.0 * (timetable.running_time / sum(plan.minimums) - 1.0)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
