#!/usr/bin/env python3
"""The least-energy run of a journey by an independent dynamic programme
(ato_nodes/studies/energy_optimum.py), against grids, and the project's planned sections
against it.

    python scripts/energy_optimum.py metro-line
    python scripts/energy_optimum.py metro-line --grid 20:0.05 --compare
    python scripts/energy_optimum.py --line LINE.yaml --train TRAIN --time 300

TIMETABLE is a timetable file, or the name of one in msg_config/timetables/: its line, its
train (--train: another preset, or a train file) and its running time (--time: another
total, s). --line takes a line file instead: its stations are the stops, --time (s) the
running time, no dwells needed. Prints, for every grid DS:DV (stage length m, speed step
m/s) of --grid, the journey's least energy with one price of time for all sections, the
sections' times, and how far it moved from the grid before; --compare then drives each
section by the project's planner (core/targets/journey.py) in its allocated time and sets
its energy against the programme of this script at the same time, on the same problem
(--like-planner: the planner keeps profile.ato.margin under the limits and its run starts
moving at once, the departure time added) and as the line allows; --like-ato SCENARIO: the
problem the scenario's ATO drives (its train, margin, envelope share, the ato curve's
planned acceleration and braking as force caps, its departure time); --times T,T,...: each
section's least energy alone in its time (e.g. a tracked run's). The energy is the traction
energy at the pantograph (--objective traction, the planner's), or the net energy of the
scorer (--objective net: less what the braking regenerates, plant.regenerative_*).
Bad input: one line, exit 2.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.paths import config_dir
from ato_nodes.core.config.scenario import complete, prepare
from ato_nodes.core.scoring.operation import Regeneration
from ato_nodes.core.targets import journey
from ato_nodes.core.targets.profiles import departure_time
from ato_nodes.core.targets.timetable import check_minimum_times, load_timetable
from ato_nodes.core.train.line import load_line
from ato_nodes.core.train.plant import TrainParameters
from ato_nodes.studies import energy_optimum as optimum

DEFAULT_GRID = "40:0.1,20:0.1,20:0.05,20:0.025,10:0.025,10:0.0125"


def parse_args():
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("timetable", metavar="TIMETABLE", nargs="?",
                        help="timetable file, or its name in msg_config/timetables/")
    parser.add_argument("--line", help="a line file instead of a timetable")
    parser.add_argument("--train", help="train preset or file (default: the timetable's)")
    parser.add_argument("--time", type=float, help="the journey's running time, s")
    parser.add_argument("--grid", default=DEFAULT_GRID, help="grids DS:DV, comma-separated "
                        f"(default {DEFAULT_GRID})")
    parser.add_argument("--objective", choices=("traction", "net"), default="traction")
    parser.add_argument("--like-planner", action="store_true", help="the planner's problem: "
                        "profile.ato.margin under the limits, the departure time added")
    parser.add_argument("--like-ato", metavar="SCENARIO", help="the problem SCENARIO's ATO "
                        "drives: its train and timetable (unless given), profile.ato.margin "
                        "under the limits, the envelope at profile.envelope_share with its "
                        "forces capped at the curve's planned acceleration and braking, the "
                        "departure time added")
    parser.add_argument("--compare", action="store_true", help="the planner's sections "
                        "at their allocated times against the programme (the last grid)")
    parser.add_argument("--times", help="each section's running time, s, comma-separated")
    return parser.parse_args()


def grids(text: str) -> list[tuple[float, float]]:
    try:
        found = [tuple(float(x) for x in item.split(":")) for item in text.split(",")]
    except ValueError:
        found = []
    if not found or any(len(g) != 2 or not (g[0] > 0 and g[1] > 0) for g in found):
        raise ScenarioError(f"--grid {text!r}: give DS:DV pairs above 0, e.g. 20:0.05")
    return found


def given(name: str | None, folder: str) -> Path | None:
    if name is None:
        return None
    path = Path(name)
    return path if path.suffix or len(path.parts) > 1 else config_dir() / folder / f"{name}.yaml"


def load(args):
    """(line, stop positions, running time, values, timetable or None)."""
    if args.like_ato:
        return like_ato(args)
    if (args.timetable is None) == (args.line is None):
        raise ScenarioError("give a TIMETABLE or --line, one of them")
    timetable = None
    if args.line:
        line = load_line(args.line)
        stops = [station.position for station in line.stations]
        if args.time is None or len(stops) < 2:
            raise ScenarioError("--line needs --time and a line with two stations or more")
        train = args.train or "metro-b"
    else:
        timetable = load_timetable(given(args.timetable, "timetables"))
        line, train = timetable.line, args.train or timetable.train
        stops = [stop.position for stop in timetable.stops]
    values = complete({"plant.train": str(given(train, "trains")) if Path(train).suffix
                       else train}, [])
    total = args.time if args.time is not None else timetable.running_time
    if not total > 0.0:
        raise ScenarioError(f"--time {total:g}: a running time above 0 s")
    return line, stops, total, values, timetable


def like_ato(args):
    """load() for --like-ato: the scenario's values, its timetable unless one is given."""
    if args.line or args.train:
        raise ScenarioError("--like-ato takes the scenario's line and train: no --line, --train")
    values = prepare(args.like_ato)
    if not (args.timetable or values["profile.journey.timetable"]):
        raise ScenarioError(f"--like-ato {args.like_ato}: not a journey; give its TIMETABLE")
    timetable = load_timetable(given(args.timetable, "timetables") if args.timetable
                               else values["profile.journey.timetable"])
    total = args.time if args.time is not None else timetable.running_time
    return (timetable.line, [stop.position for stop in timetable.stops], total, values,
            timetable)


def ato_limited(train: TrainParameters, values) -> TrainParameters:
    """The train as the scenario's ato curve may drive it (--like-ato): its envelope at
    profile.envelope_share, the forces at most what gives the curve's planned acceleration
    and braking on the level (mass x (1 + rotating share) x rate)."""
    share = values["profile.envelope_share"] or 1.0
    inertia = train.mass * (1.0 + train.gamma)
    return dataclasses.replace(
        train, max_traction_force=min(share * train.max_traction_force,
                                      inertia * values["profile.ato.acceleration"]),
        max_traction_power=share * train.max_traction_power,
        max_brake_force=min(share * train.max_brake_force,
                            inertia * values["profile.ato.deceleration"]),
        max_brake_power=share * train.max_brake_power)


def sections_of(line, stops, values, args, ds, dv):
    train = TrainParameters.from_values(values)
    if args.like_ato:
        train = ato_limited(train, values)
    regeneration = (Regeneration(force=0.0) if args.objective == "traction"
                    else Regeneration.of(values))
    margin = values["profile.ato.margin"] if args.like_planner or args.like_ato else 0.0
    return optimum.sections_between(line, stops, train, values["plant.efficiency"],
                                    regeneration, ds, dv, margin)


def departure(values, args) -> float:
    return departure_time(values, TrainParameters.from_values(values)) \
        if args.like_planner or args.like_ato else 0.0


def study(line, stops, total, values, args, levels):
    """The grid study's table; the last grid's sections."""
    moving = total - departure(values, args) * (len(stops) - 1)
    print(f"{line.name}: {len(stops) - 1} sections, running time {total:g} s "
          f"({moving:.1f} s moving), objective {args.objective} energy"
          + (", the planner's problem" if args.like_planner else ""))
    print("| ds m | dv m/s | kWh | change | price kW | section times s | seconds |")
    print("|---|---|---|---|---|---|---|")
    previous, sections, price = None, None, None
    for ds, dv in levels:
        started = time.monotonic()
        sections = sections_of(line, stops, values, args, ds, dv)
        found = optimum.journey_optimum(sections, moving, price)
        price = found.price
        energy = found.net_kwh
        change = "" if previous is None else f"{100 * (energy / previous - 1):+.2f} %"
        times = ", ".join(f"{run.time + departure(values, args):.1f}" for run in found.early)
        print(f"| {ds:g} | {dv:g} | {energy:.3f} | {change} | {found.price:.1f} | {times} | "
              f"{time.monotonic() - started:.0f} |")
        previous = energy
    fastest = [optimum.run_at(section, optimum.HIGHEST_PRICE) for section in sections]
    print(f"minimum-time run: {sum(run.time for run in fastest) + total - moving:.1f} s, "
          f"{sum(run.net_kwh for run in fastest):.3f} kWh ({args.objective})")
    return sections


def compare(timetable, values, sections, args) -> None:
    """The planner's sections at their allocated times against the programme."""
    plan = journey.plan_journey(timetable, values, check_minimum_times(timetable, values))
    print(f"\nplanned sections against the programme ({args.objective}"
          + (", the planner's problem)" if args.like_planner else ", the line as it is)"))
    print("| section | allocated s | planner kWh | optimum kWh | difference |")
    print("|---|---|---|---|---|")
    for run, problem, section, allocated in zip(plan.driven, plan.sections, sections,
                                                plan.allocation.times, strict=True):
        moving = run.time + problem.departure - departure(values, args)
        best = optimum.journey_optimum([section], moving).net_kwh
        print(f"| {problem.section.origin} - {problem.section.destination} | {allocated:.1f} | "
              f"{run.energy_kwh:.3f} | {best:.3f} | {100 * (run.energy_kwh / best - 1):+.2f} % |")
    print(f"journey: planner {plan.energy_kwh:.3f} kWh")


def section_times(text: str | None, count: int) -> list[float] | None:
    """--times' running times, one a section, s (None: not given)."""
    if text is None:
        return None
    try:
        times = [float(x) for x in text.split(",")]
    except ValueError:
        times = []
    if len(times) != count or not all(math.isfinite(t) and t > 0.0 for t in times):
        raise ScenarioError(f"--times {text!r}: {count} running times above 0 s, "
                            "comma-separated")
    return times


def each(times: list[float], sections, values, args) -> None:
    print("\n| section | s | optimum kWh |\n|---|---|---|")
    total = 0.0
    for i, (section, seconds) in enumerate(zip(sections, times, strict=True)):
        energy = optimum.journey_optimum([section], seconds - departure(values, args)).net_kwh
        total += energy
        print(f"| {i + 1} | {seconds:.1f} | {energy:.3f} |")
    print(f"sum: {sum(times):.1f} s, {total:.3f} kWh")


def main() -> None:
    args = parse_args()
    try:
        levels = grids(args.grid)
        line, stops, total, values, timetable = load(args)
        times = section_times(args.times, len(stops) - 1)
        if args.compare and timetable is None:
            raise ScenarioError("--compare needs a TIMETABLE (the planner's allocation)")
        sections = study(line, stops, total, values, args, levels)
        if args.compare:
            compare(timetable, values, sections, args)
        if times:
            each(times, sections, values, args)
    except (ScenarioError, ValueError) as exc:
        _cli.fail(str(exc))


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
