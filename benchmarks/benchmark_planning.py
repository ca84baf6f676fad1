#!/usr/bin/env python3
"""Planning cost per train: milliseconds per prepare() of each scenario named (default:
the -ato interstations and the journeys), each call for a train of its own (a different
plant.mass_factor, so no cache of plans serves it); then load_scenario of every shipped
scenario once. Prints figures, asserts nothing.

    python benchmarks/benchmark_planning.py [SCENARIO ...] [--trains 5]

The first call of each scenario is a warm-up (the compiled planner loaded from its
cache, the line parsed); the median of the --trains timed calls after it is printed.
"""

from __future__ import annotations

import time

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import load_scenario, prepare, scenario_names

PLANNED = ("seed000-ato", "seed000-realistic-ato", "seed001-crh380al-ato", "seed002-hsr-ato",
           "seed003-maglev-ato", "seed004-metro-ato", "hsr-neutral-ato",
           "seed004-metro-line", "seed002-journey")


def per_train(name: str, trains: int) -> float:
    """Median seconds of prepare(`name`) over `trains` trains, each of its own mass."""
    prepare(name, {"plant.mass_factor": 1.0})
    return _cli.median_seconds(
        lambda train: prepare(name, {"plant.mass_factor": 1.01 + 0.01 * train}), trains)


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenarios", nargs="*", metavar="SCENARIO")
    parser.add_argument("--trains", type=int, default=5)
    args = parser.parse_args()
    try:
        print(f"{'scenario':24s} {'ms/prepare':>10s}")
        for name in args.scenarios or PLANNED:
            print(f"{name:24s} {per_train(name, args.trains) * 1e3:10.1f}", flush=True)
        started = time.perf_counter()
        for name in scenario_names():
            load_scenario(name)
        print(f"load_scenario of all {len(scenario_names())}: "
              f"{time.perf_counter() - started:.2f} s")
    except ScenarioError as exc:
        _cli.fail(str(exc))


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
