#!/usr/bin/env python3
"""Compare optimizers tuning the same controller: equal budgets, several seeds.

    python scripts/compare_tuners.py --algorithms bas-pso pso wso --seeds 1 2 3 4 5 \\
        --evaluations 900 --params adrc.mu1=600:60000,... --out bags/compare-seed000

Equal budgets are equal evaluations (--evaluations) or equal iterations (--iterations N:
each algorithm gets what its initialisation and N iterations evaluate, e.g. for 30
particles 330 for PSO and 930 for BAS-PSO, whose beetles probe two antennae per move;
a paper's convergence figure plots iterations).

Each (algorithm, seed) is a tune.py run (in-process; an existing finished one in
--out is reused), then the best parameters of each algorithm are re-run through
the real stack and the bag's ITAE is set beside the tuner's. Prints and writes
(comparison.md) a table of ITAE and max |e| per algorithm, with seed 000's
figures beside them, and a convergence plot of every run.
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

import _cli

from ato_nodes.reports.analysis import plot_convergence
from ato_nodes.bags.bagio import read_run
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.optimizers import create
from ato_nodes.core.config.scenario import apply_overrides, prepare
from ato_nodes.core.run.scoring import score_series
from ato_nodes.launcher.launch import Stack
from ato_nodes.studies.runner import write_outputs
from ato_nodes.studies.tuning import SearchSpace, Tuner, TuningSettings

PAPER_MAX_ERROR = {  # seed 000's reported tracking errors, km/h
    "bas-pso": "±0.05 (body), ±0.4 (abstract)",
    "wso": "about ±0.2 (improved shark)",
    "pso": "up to ±4",
}


def parse_args() -> argparse.Namespace:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--algorithms", nargs="+", default=["bas-pso", "pso", "wso"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3, 4, 5])
    budget = parser.add_mutually_exclusive_group(required=True)
    budget.add_argument("--evaluations", type=int, help="budget of every run")
    budget.add_argument("--iterations", type=int, help="iterations of every run")
    parser.add_argument("--population", type=int, default=30)
    parser.add_argument("--scenario", default="seed000")
    parser.add_argument("--params", action="append", required=True)
    parser.add_argument("--set", action="append", default=[])
    parser.add_argument("--fitness", default="itae")
    parser.add_argument("--options", action="append", default=[],
                        metavar="ALGORITHM:NAME=VALUE,...", help="an algorithm's options "
                        "(repeatable), e.g. pso:c1=2,c2=2,w_start=0.6,w_end=0.6")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    return parser.parse_args()


def algorithm_options(args, algorithm: str) -> dict:
    """population_size and the --options given for `algorithm`."""
    options = {"population_size": args.population}
    for text in args.options:
        name, _, assignments = text.partition(":")
        if name != algorithm:
            continue
        for assignment in assignments.split(","):
            key, sep, value = assignment.partition("=")
            try:
                options[key.strip()] = float(value)
            except ValueError:
                _cli.fail(f"--options {text}: expected NAME=NUMBER, got {assignment!r}")
            if not sep:
                _cli.fail(f"--options {text}: expected NAME=NUMBER, got {assignment!r}")
    try:
        create(algorithm, **options)
    except (TypeError, ValueError) as exc:
        _cli.fail(f"--options for {algorithm}: {exc}")
    return options


def budget(args, algorithm: str) -> int:
    """Evaluations of one run: --evaluations, or what --iterations take this algorithm."""
    if args.evaluations is not None:
        return args.evaluations
    optimizer = create(algorithm, **algorithm_options(args, algorithm))
    return optimizer.initial_evaluations() + args.iterations * optimizer.evaluations_per_iteration()


def tune(args, values, space, algorithm: str, seed: int) -> dict:
    out = args.out / f"{algorithm}-seed{seed}"
    if (out / "summary.json").exists():
        return json.loads((out / "summary.json").read_text())
    settings = TuningSettings(algorithm, args.scenario, space, budget(args, algorithm), seed,
                              args.workers, True, args.fitness,
                              options=algorithm_options(args, algorithm))
    Tuner(values, settings, out, resume=True, progress=False).run()
    return json.loads((out / "summary.json").read_text())


def stack_check(values, best: dict, bag: Path) -> float:
    """ITAE of the best parameters re-run through the real node graph."""
    if not bag.exists():
        outcome = Stack(apply_overrides(values, best), bag, quiet=True).run()
        if not outcome.ok:
            _cli.fail(f"stack re-run of {bag.name} failed: {outcome.message}", 1)
    run = read_run(bag)
    return score_series(run.series, run.parameters)["itae"]


def main() -> None:
    args = parse_args()
    try:
        values = prepare(args.scenario, args.set)
        space = SearchSpace.parse(args.params, values)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    args.out.mkdir(parents=True, exist_ok=True)
    rows = ["| algorithm | runs | evaluations | ITAE median | ITAE best | "
            "max abs(e) km/h median | max abs(e) km/h best | stack re-run ITAE (best) | "
            "paper's max error |", "|---|---|---|---|---|---|---|---|---|"]
    for algorithm in args.algorithms:
        algorithm_options(args, algorithm)  # a bad option fails now, before any tuning
    for algorithm in args.algorithms:
        summaries = []
        for seed in args.seeds:
            summary = tune(args, values, space, algorithm, seed)
            summaries.append(summary)
            print(f"{algorithm} seed {seed}: ITAE {summary['best_indices']['itae']:.6g}, "
                  f"max |e| {summary['best_indices']['max_abs_error_kmh']:.4f} km/h", flush=True)
        itae = [s["best_indices"]["itae"] for s in summaries]
        max_error = [s["best_indices"]["max_abs_error_kmh"] for s in summaries]
        best = min(summaries, key=lambda s: s["best_fitness"])
        stack_itae = stack_check(values, best["best_params"], args.out / f"{algorithm}-best-stack")
        agreement = abs(stack_itae - best["best_indices"]["itae"]) / best["best_indices"]["itae"]
        rows.append(f"| {algorithm} | {len(summaries)} | {budget(args, algorithm)} | "
                    f"{statistics.median(itae):.6g} | "
                    f"{min(itae):.6g} | {statistics.median(max_error):.4f} | "
                    f"{min(max_error):.4f} | "
                    f"{stack_itae:.6g} (rel. diff {agreement:.1e}) | "
                    f"{PAPER_MAX_ERROR.get(algorithm, '-')} |")
    table = "\n".join(rows)
    spent = (f"{args.evaluations} evaluations" if args.evaluations is not None
             else f"{args.iterations} iterations")
    write_outputs(args.out, "comparison", markdown=(
        f"Budget {spent} each, population {args.population}, seeds "
        f"{' '.join(map(str, args.seeds))}, fitness {args.fitness}, scenario {args.scenario} "
        f"{' '.join(args.set)}; options {' '.join(args.options) or 'the defaults'}\n\n{table}"))
    plot_convergence(sorted(p for p in args.out.iterdir() if (p / "history.csv").exists()),
                     args.out / "convergence.png")
    print(table)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
