#!/usr/bin/env python3
"""Speed of tuning on this machine (prints figures; asserts nothing).

    python scripts/benchmark_tuning.py [--candidates 4] [--baspso]

Measures: the per-candidate overhead of relaunching the node graph (a one-step
run, start to exit), stack-mode candidates per minute on the full seed-000 run
with 1 and 2 workers, in-process evaluations per second of the full run with 1
and 2 workers, and with --baspso the wall time of a full in-process BAS-PSO
tuning of the seed-000 ADRC, 30 particles for 30 iterations.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import _cli  # noqa: F401  (repo on sys.path)

from ato_nodes.core.scenario import apply_overrides, load_scenario
from ato_nodes.launch import Stack
from ato_nodes.tuning import SearchSpace, Tuner, TuningSettings, evaluate_in_process

SEED000_SPACE = ("adrc.mu1=600:60000,adrc.mu2=550:55000,adrc.beta1=120:12000,"
                 "adrc.beta2=170:17000,adrc.beta3=450:45000,adrc.b0=0.02:2,adrc.r0=0.5:500,"
                 "adrc.h0=0.0005:0.2")


def candidates(count: int) -> list[dict]:
    """Distinct, stable candidates around the paper's gains."""
    return [{"adrc.mu1": 6000.0 + 100.0 * i} for i in range(count)]


def stack_rate(values, count: int, workers: int, tmp: Path) -> float:
    def one(index_and_overrides):
        index, overrides = index_and_overrides
        outcome = Stack(apply_overrides(values, overrides), tmp / f"w{workers}-{index}",
                        quiet=True).run()
        assert outcome.ok, outcome.message
    started = time.monotonic()
    with ThreadPoolExecutor(workers) as pool:
        list(pool.map(one, enumerate(candidates(count))))
    return count / (time.monotonic() - started) * 60.0


def in_process_rate(values, count: int, workers: int) -> float:
    started = time.monotonic()
    with ProcessPoolExecutor(workers) as pool:
        list(pool.map(evaluate_in_process, [values] * count, candidates(count),
                      ["itae"] * count, range(count)))
    return count / (time.monotonic() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--candidates", type=int, default=4, help="stack candidates per setting")
    parser.add_argument("--baspso", action="store_true", help="also time a 30 x 30 BAS-PSO run")
    args = parser.parse_args()
    values = load_scenario("seed000")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        overheads = []
        for index in range(3):
            outcome = Stack(apply_overrides(values, ["run.duration=0.05"]), tmp / f"one-{index}",
                            quiet=True).run()
            overheads.append(outcome.wall_time - outcome.report["loop_wall_time"])
        print(f"relaunch overhead per candidate (start, match, stop; one-step run): "
              f"median {statistics.median(overheads):.2f} s of {', '.join(f'{o:.2f}' for o in overheads)}"
              " (target < 2 s)")
        for workers in (1, 2):
            rate = stack_rate(values, args.candidates, workers, tmp)
            print(f"stack mode, full 2400 s seed-000 candidates, {workers} worker(s): "
                  f"{rate:.2f} candidates/min")
    for workers in (1, 2):
        rate = in_process_rate(values, 4 * workers, workers)
        print(f"in-process, full 2400 s seed-000 run, {workers} worker(s): {rate:.2f} evaluations/s")
    if args.baspso:
        with tempfile.TemporaryDirectory() as tmp:
            settings = TuningSettings("bas-pso", "seed000", SearchSpace.parse([SEED000_SPACE]),
                                      evaluations=30 + 30 * 3 * 30, seed=1, workers=2,
                                      in_process=True, options={"population_size": 30})
            started = time.monotonic()
            result = Tuner(values, settings, Path(tmp), progress=False).run()
            wall = time.monotonic() - started
        print(f"BAS-PSO 30 particles x 30 iterations ({result.evaluations} evaluations, "
              f"antennae included), in-process, 2 workers: {wall:.0f} s (target < 600 s)")


if __name__ == "__main__":
    main()
