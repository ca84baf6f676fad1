#!/usr/bin/env python3
"""In-process cost per simulated step of every shipped scenario (or those named): prints
figures, asserts nothing.

    python benchmarks/benchmark_steps.py [SCENARIO ...] [--seconds 300] [--repeats 3]

Each run is cut to --seconds of simulated time (the whole run where shorter), run once
to warm up (loading the compiled loop, building the plan), then timed --repeats times in
the same process; the median per step is printed, with whether the run was compiled.
--python times the same loop run as Python (simulate(compiled=False)).
"""

from __future__ import annotations

import statistics
import time

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, prepare, scenario_names
from ato_nodes.core.run import fast_loop
from ato_nodes.core.run.loop import simulate


def per_step(values: dict, repeats: int, compiled: bool) -> tuple[float, int]:
    """(median seconds per step of `repeats` timed runs after a warm-up, steps a run)."""
    steps = len(simulate(values, compiled=compiled)["t"])
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        simulate(values, compiled=compiled)
        times.append(time.perf_counter() - started)
    return statistics.median(times) / steps, steps


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenarios", nargs="*", metavar="SCENARIO")
    parser.add_argument("--seconds", type=float, default=300.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--python", action="store_true", help="time the Python loop")
    args = parser.parse_args()
    try:
        runs = {}
        for name in args.scenarios or scenario_names():
            values = prepare(name)
            runs[name] = apply_overrides(values, {
                "run.duration": min(args.seconds, values["run.duration"])})
    except ScenarioError as exc:
        _cli.fail(str(exc))
    print(f"{'scenario':24s} {'us/step':>9s}  steps  loop")
    for name, values in runs.items():
        compiled = not args.python and fast_loop.AVAILABLE
        seconds, steps = per_step(values, args.repeats, not args.python)
        print(f"{name:24s} {seconds * 1e6:9.2f} {steps:6d}  {'compiled' if compiled else 'Python'}",
              flush=True)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
