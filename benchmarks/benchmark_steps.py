#!/usr/bin/env python3
"""In-process cost of every shipped scenario (or those named), in two columns: prints
figures, asserts nothing.

    python benchmarks/benchmark_steps.py [SCENARIO ...] [--seconds 300] [--repeats 3]
        [--set NAME=VALUE ...]

us/step: simulate() of the run, cut to --seconds of simulated time (the whole run where
shorter), per step, with its plan already built (a warm-up run loads the compiled loop
and builds the plan, which every later run of the same inputs reads from the process's
cache of plans): the loop, and the stages' construction and the series around it; the
median of --repeats timed runs, with whether the loop was compiled. --python times the
same loop run as Python (simulate(compiled=False)).

plan ms: building the run's plan anew (the profile's run context's plan, the caches of
plans emptied first: core/config/context.py forget_plans), the median of --repeats; the
first build of each scenario, which loads its compiled planning kernels, is not timed.
"""

from __future__ import annotations

import statistics
import time

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext, forget_plans
from ato_nodes.core.config.scenario import apply_overrides, prepare, scenario_names
from ato_nodes.core.config.schema import NodeValues
from ato_nodes.core.run import fast_loop
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.train.lines import line_of


def per_step(values: dict, repeats: int, compiled: bool) -> tuple[float, int]:
    """(median seconds per step of `repeats` timed runs after a warm-up, steps a run)."""
    steps = len(simulate(values, compiled=compiled)["t"])
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        simulate(values, compiled=compiled)
        times.append(time.perf_counter() - started)
    return statistics.median(times) / steps, steps


def plan_seconds(values: dict, repeats: int) -> float:
    """Median seconds of building the run's plan anew, `repeats` times after a warm-up."""
    line = line_of(values)
    times = []
    for _ in range(repeats + 1):
        forget_plans()
        started = time.perf_counter()
        _ = RunContext(NodeValues("profile", values), line).plan
        times.append(time.perf_counter() - started)
    return statistics.median(times[1:])


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenarios", nargs="*", metavar="SCENARIO")
    parser.add_argument("--seconds", type=float, default=300.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--python", action="store_true", help="time the Python loop")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a parameter in every run (repeatable)")
    args = parser.parse_args()
    try:
        runs = {}
        for name in args.scenarios or scenario_names():
            values = prepare(name, args.set)
            runs[name] = apply_overrides(values, {
                "run.duration": min(args.seconds, values["run.duration"])})
    except ScenarioError as exc:
        _cli.fail(str(exc))
    print(f"{'scenario':24s} {'us/step':>9s}  steps  loop      {'plan ms':>8s}")
    for name, values in runs.items():
        compiled = not args.python and fast_loop.AVAILABLE
        seconds, steps = per_step(values, args.repeats, not args.python)
        planning = plan_seconds(values, args.repeats)
        print(f"{name:24s} {seconds * 1e6:9.2f} {steps:6d}  "
              f"{'compiled' if compiled else 'Python  '}  {planning * 1e3:8.1f}", flush=True)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
