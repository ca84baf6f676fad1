#!/usr/bin/env python3
"""One whole run in-process, planning apart from simulating: prints figures, asserts
nothing.

    python benchmarks/benchmark_line_run.py [SCENARIO] [--repeats 5]

SCENARIO (default yizhuang-line: the real Yizhuang line's 13 sections) is prepared once
(a warm-up: the compiled planner and loop loaded from their caches, the line and the
timetable read), then each figure is the median of --repeats:

  plan      the run's plan built anew (the caches of plans emptied first:
            core/config/context.py forget_plans): the profile's run context's plan
  prepare   prepare() of the scenario for a train of its own (plant.mass_factor 1.3 and
            a weighed reading: its own plan, no cache serves it): validation with its plan
  simulate  simulate() of the whole run with its plan built (the loop, the stages'
            construction and the series around it)
  score     the run scored with its journey (core/scoring/journey.py where it has one)
"""

from __future__ import annotations


import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext, forget_plans
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.config.schema import NodeValues
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.train.lines import line_of
from ato_nodes.results.journeys import score_with_journey


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenario", nargs="?", default="yizhuang-line")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    if args.repeats < 1:
        _cli.fail("--repeats must be at least 1")
    try:
        values = prepare(args.scenario)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    series = simulate(values)
    line = line_of(values)

    def plan(_):
        forget_plans()
        return RunContext(NodeValues("profile", values), line).plan

    def heavy(repeat):  # a train of its own each time: no plan cached for it
        return prepare(args.scenario, {"plant.mass_factor": 1.3, "train.load_weighing": True,
                                       "train.load_weighing_seed": 100 + repeat})

    figures = {"plan": _cli.median_seconds(plan, args.repeats),
               "prepare": _cli.median_seconds(heavy, args.repeats)}
    prepare(args.scenario)  # its plan cached again
    figures["simulate"] = _cli.median_seconds(lambda _: simulate(values), args.repeats)
    figures["score"] = _cli.median_seconds(lambda _: score_with_journey(values, series),
                                      args.repeats)
    print(f"{args.scenario}: {len(series['t'])} steps, {series['t'][-1]:.1f} s simulated; "
          f"median of {args.repeats}")
    for name, seconds in figures.items():
        print(f"  {name:9s} {seconds:8.3f} s")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
