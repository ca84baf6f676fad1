#!/usr/bin/env python3
"""Speed of tuning on this machine (prints figures; asserts nothing).

    python benchmarks/benchmark_tuning.py [--candidates 4] [--baspso [--baspso-reference DIR]]

Measures: the per-candidate overhead of relaunching the node graph (a one-step
run, start to exit), stack-mode candidates per minute on the full seed-000 run
with 1 and 2 workers, the time of one in-process evaluation of the full run,
in-process evaluations per second with 1 and 2 workers, the Dask overhead per task
(a LocalCluster of 2 workers against the local pool, on one-step candidates; with
dask installed), and with --baspso the wall time and pruned share of a full
in-process BAS-PSO tuning of the seed-000 ADRC, 30 particles for 30 iterations;
--baspso-reference DIR checks its best, best parameters and best-so-far history
against the same tuning run without pruning, made beforehand by

    python scripts/tune.py --algorithm bas-pso --scenario seed000 --in-process \
        --params SEED000_SPACE --evaluations 2730 --population 30 --seed 1 --workers 2 \
        --no-prune --out DIR

(SEED000_SPACE as below).
"""

from __future__ import annotations

import csv
import json
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import _cli

from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.launcher.launch import Stack
from ato_nodes.studies.tuning import SearchSpace, Tuner, TuningSettings, evaluate_in_process

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
    """Evaluations per second of a warm pool (each worker has loaded the compiled loop
    and the plan's horizons once, as in a tuning)."""
    with ProcessPoolExecutor(workers) as pool:
        list(pool.map(evaluate_in_process, [values] * workers, candidates(workers),
                      ["itae"] * workers, range(workers)))
        started = time.monotonic()
        list(pool.map(evaluate_in_process, [values] * count, candidates(count),
                      ["itae"] * count, range(count)))
        return count / (time.monotonic() - started)


def dask_overhead(values, count: int = 60) -> float | None:
    """Seconds per task a Dask LocalCluster (2 workers) adds over the local pool."""
    try:
        from ato_nodes.studies.backend import open_cluster
        client, cluster = open_cluster("local:2")
    except Exception:  # no dask: nothing to measure
        return None
    one_step = apply_overrides(values, ["run.duration=0.05"])
    jobs = ([one_step] * count, candidates(count), ["itae"] * count, range(count))
    try:
        with client.get_executor(pure=False) as executor:
            list(executor.map(evaluate_in_process, *jobs))  # warm: workers import the code
            started = time.monotonic()
            list(executor.map(evaluate_in_process, *jobs))
            on_dask = time.monotonic() - started
    finally:
        client.close()
        cluster.close()
    with ProcessPoolExecutor(2) as pool:
        list(pool.map(evaluate_in_process, *jobs))
        started = time.monotonic()
        list(pool.map(evaluate_in_process, *jobs))
        local = time.monotonic() - started
    return (on_dask - local) / count * 2  # two tasks run at a time


def best_so_far(tuning: Path) -> list[list[str]]:
    """history.csv without its mean_fitness column (a pruned candidate's is a bound)."""
    with (tuning / "history.csv").open() as handle:
        rows = list(csv.reader(handle))
    drop = rows[0].index("mean_fitness")
    return [row[:drop] + row[drop + 1:] for row in rows]


def print_stack_figures(values: dict, candidates_per_setting: int) -> None:
    """The relaunch overhead of one-step candidates, then stack candidates per minute."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        overheads = []
        for index in range(6):
            outcome = Stack(apply_overrides(values, ["run.duration=0.05"]), tmp / f"one-{index}",
                            quiet=True).run()
            overheads.append(outcome.wall_time - outcome.report["loop_wall_time"])
        print(f"relaunch overhead per candidate (start, match, stop; one-step run; the first "
              f"starts the fork server): median {statistics.median(overheads):.2f} s of "
              f"{', '.join(f'{o:.2f}' for o in overheads)} (target <= 0.5 s)")
        for workers in (1, 2):
            rate = stack_rate(values, candidates_per_setting, workers, tmp)
            print(f"stack mode, full 2400 s seed-000 candidates, {workers} worker(s): "
                  f"{rate:.2f} candidates/min")


def print_in_process_figures(values: dict) -> None:
    """One evaluation's time, evaluations per second, the Dask overhead per task."""
    times = []
    for index in range(6):
        started = time.perf_counter()
        evaluate_in_process(values, candidates(index + 1)[-1], "itae", index)
        times.append(time.perf_counter() - started)
    print(f"one in-process evaluation of the full 2400 s seed-000 run: median "
          f"{statistics.median(times[1:]):.3f} s (target <= 0.15 s; the first, which loads the "
          f"compiled loop and computes the plan's horizons: {times[0]:.2f} s)")
    for workers in (1, 2):
        rate = in_process_rate(values, 40 * workers, workers)
        print(f"in-process, full 2400 s seed-000 run, {workers} worker(s): "
              f"{rate:.2f} evaluations/s")
    overhead = dask_overhead(values)
    print("Dask overhead per task (LocalCluster, 2 workers): "
          + (f"{overhead * 1000:.1f} ms" if overhead is not None else "dask not installed"))


def print_baspso_figures(values: dict, reference: Path | None) -> None:
    """A full BAS-PSO tuning's wall time and pruned share; with `reference` (the same
    tuning without pruning), whether both found the same."""
    with tempfile.TemporaryDirectory() as tmp:
        settings = TuningSettings("bas-pso", "seed000", SearchSpace.parse([SEED000_SPACE]),
                                  evaluations=30 + 30 * 3 * 30, seed=1, workers=2,
                                  in_process=True, options={"population_size": 30})
        started = time.monotonic()
        result = Tuner(values, settings, Path(tmp), progress=False).run()
        wall = time.monotonic() - started
        summary = json.loads((Path(tmp) / "summary.json").read_text())
        history = best_so_far(Path(tmp))
    print(f"BAS-PSO 30 particles x 30 iterations ({result.evaluations} evaluations, "
          f"antennae included), in-process, 2 workers: {wall:.0f} s (target <= 180 s), "
          f"pruned {summary['pruned_evaluations'] / result.evaluations:.0%}, "
          f"best ITAE {result.best_f!r}")
    if reference:
        expected = json.loads((reference / "summary.json").read_text())
        same = (expected["best_fitness"] == summary["best_fitness"]
                and expected["best_params"] == summary["best_params"]
                and best_so_far(reference) == history)
        print(f"same best, best parameters and best-so-far history as the tuning without "
              f"pruning in {reference} ({expected['wall_time']:.0f} s): "
              + ("yes" if same else "NO"))


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--candidates", type=int, default=4, help="stack candidates per setting")
    parser.add_argument("--baspso", action="store_true", help="also time a 30 x 30 BAS-PSO run")
    parser.add_argument("--baspso-reference", type=Path, metavar="DIR",
                        help="the same BAS-PSO tuning without pruning (see above) to compare with")
    args = parser.parse_args()
    values = load_scenario("seed000")
    print_stack_figures(values, args.candidates)
    print_in_process_figures(values)
    if args.baspso:
        print_baspso_figures(values, args.baspso_reference)

if __name__ == "__main__":
    main()
