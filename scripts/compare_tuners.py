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

With --objectives (and --reference, the hypervolume's reference point in the objectives'
units, the same for every run) the algorithms are multi-objective (nsga2, nsga3) or a
swarm optimizer on their weighted sum (each objective over its reference value: the
scalarised baseline), every run judged alike: the hypervolume of the feasible
non-dominated set of every candidate it evaluated. The table gives its median and spread,
and the hypervolume of each algorithm's median attainment surface (what at least half its
runs reached); attainment.csv holds the best, median and worst surfaces, attainment.png
draws them with two objectives:

    python scripts/compare_tuners.py --algorithms nsga2 pso --seeds 1 2 3 --evaluations 200 \
        --scenario seed004-metro-ato --params ladrc.omega_o=1:40,ladrc.omega_c=1:10 \
        --objectives energy,p95_abs_error_kmh --reference 30,0.5 \
        --require 'abs_stopping_error<=0.1' --population 20 --out bags/compare-fronts
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
from pathlib import Path

import numpy as np

import _cli

from ato_nodes.reports.analysis import plot_convergence
from ato_nodes.bags.bagio import read_run
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.optimizers import create
from ato_nodes.core.config.scenario import apply_overrides, prepare
from ato_nodes.core.run.scoring import score_series
from ato_nodes.launcher.launch import Stack
from ato_nodes.studies.runner import write_outputs
from ato_nodes.core.optimizers.pareto import (MEDIAN_ATTAINMENT, PARETO_ALGORITHMS,
                                              attainment, hypervolume, nondominated)
from ato_nodes.reports.pareto import plot_attainment
from ato_nodes.core.scoring.catalogue import Requirement
from ato_nodes.studies.pareto_tuning import Choice, ParetoTuner
from ato_nodes.studies.tuning import (Evaluation, Objectives, SearchSpace, Tuner,
                                      TuningSettings)

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
    parser.add_argument("--objectives", metavar="NAME,NAME[,...]", help="several "
                        "objectives (tune.py's): compare hypervolumes")
    parser.add_argument("--reference", metavar="V,V[,...]", help="with --objectives: the "
                        "hypervolume's reference point, the same for every run")
    parser.add_argument("--require", action="append", default=[], metavar="INDEX<=VALUE")
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
        if algorithm not in PARETO_ALGORITHMS:
            create(algorithm, **options)
    except (TypeError, ValueError) as exc:
        _cli.fail(f"--options for {algorithm}: {exc}")
    return options


def budget(args, algorithm: str) -> int:
    """Evaluations of one run: --evaluations, or what --iterations take this algorithm."""
    if args.evaluations is not None:
        return args.evaluations
    if algorithm in PARETO_ALGORITHMS:
        return args.iterations * args.population
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
        if args.objectives:
            compare_fronts(args, values, space)
            return
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


def front_tuning(args, values, space, algorithm: str, seed: int, objectives: tuple[str, ...],
                 reference: tuple[float, ...]) -> Path:
    """One (algorithm, seed) run of a comparison of fronts (an existing finished one in
    --out is reused): multi-objective, or a swarm on the objectives' weighted sum (each
    over its reference value)."""
    out = args.out / f"{algorithm}-seed{seed}"
    if (out / "summary.json").exists():
        return out
    weights = () if algorithm in PARETO_ALGORITHMS else tuple(
        1.0 / max(abs(value), 1e-12) for value in reference)
    settings = TuningSettings(algorithm, args.scenario, space, budget(args, algorithm), seed,
                              args.workers, True, options=algorithm_options(args, algorithm),
                              requirements=tuple(map(Requirement.parse, args.require)),
                              objectives=objectives, weights=weights)
    if weights:
        Tuner(values, settings, out, resume=True, progress=False).run()
    else:
        ParetoTuner(values, settings, out, Choice(reference=reference), resume=True,
                    progress=False).run()
    return out


def run_front(out: Path, objective: Objectives) -> np.ndarray:
    """The feasible non-dominated set (minimised form) of every candidate a tuning in
    `out` evaluated."""
    records = [Evaluation(**json.loads(line)) for line in
               (out / "evaluations.jsonl").read_text().splitlines()]
    vectors = [objective.vector(record) for record in records]
    F = np.array([f for f, g in vectors if np.all(g <= 0.0)]).reshape(
        -1, len(objective.objectives))
    return F[nondominated(F)]


def compare_fronts(args, values, space) -> None:
    """The comparison of fronts: every (algorithm, seed), the hypervolume's median, spread
    and extremes per algorithm, and each algorithm's attainment surfaces over its seeds."""
    objectives = tuple(name.strip() for name in args.objectives.split(","))
    reference = Choice.parse(None, args.reference, len(objectives)).reference
    if reference is None:
        raise ScenarioError("--objectives needs --reference: the same point for every run")
    objective = Objectives("itae", tuple(map(Requirement.parse, args.require)), objectives)
    sense = np.array(objective.senses)
    limit = np.array(reference) * sense  # the reference point, minimised form
    args.out.mkdir(parents=True, exist_ok=True)
    rows = ["| algorithm | runs | evaluations | hypervolume median | p25 .. p75 | min .. max "
            "| front size median | median attainment's hypervolume |",
            "|---|---|---|---|---|---|---|---|"]
    surfaces = {}
    for algorithm in args.algorithms:
        fronts = [run_front(front_tuning(args, values, space, algorithm, seed, objectives,
                                         reference), objective) for seed in args.seeds]
        volumes = [hypervolume(front, limit) for front in fronts]
        for seed, volume, front in zip(args.seeds, volumes, fronts, strict=True):
            print(f"{algorithm} seed {seed}: hypervolume {volume:.6g}, front {len(front)}",
                  flush=True)
        surfaces[algorithm] = attainment(fronts, attainment_levels(len(fronts)))
        low, middle, high = np.quantile(volumes, [0.25, 0.5, 0.75])
        median = hypervolume(surfaces[algorithm][MEDIAN_ATTAINMENT], limit)
        rows.append(f"| {algorithm} | {len(volumes)} | {budget(args, algorithm)} | "
                    f"{middle:.6g} | {low:.6g} .. {high:.6g} | {min(volumes):.6g} .. "
                    f"{max(volumes):.6g} | {statistics.median(map(len, fronts)):g} | "
                    f"{median:.6g} |")
    write_attainment(args.out, objective, surfaces)
    table = "\n".join(rows)
    write_outputs(args.out, "comparison", markdown=(
        f"Objectives {', '.join(objectives)} against the reference point "
        f"({args.reference}); requirements {', '.join(args.require) or 'none'}; seeds "
        f"{' '.join(map(str, args.seeds))}, population {args.population}, scenario "
        f"{args.scenario} {' '.join(args.set)}; a swarm optimizer minimises the objectives' "
        f"sum, each over its reference value; every run's hypervolume is that of the "
        f"feasible non-dominated set of every candidate it evaluated; the median "
        f"attainment surface is what at least half the runs reached (attainment.csv: "
        f"the best, median and worst surfaces)\n\n{table}"))
    print(table)


def attainment_levels(runs: int) -> tuple[float, ...]:
    """The attainment percentiles reported: the best any run reached, the median, what
    every run reached."""
    return tuple(sorted({100.0 / runs, MEDIAN_ATTAINMENT, 100.0}))


def write_attainment(out: Path, objective: Objectives, surfaces: dict) -> None:
    """attainment.csv (algorithm, percentile, the objectives in their own units and
    sense) and, with two objectives, attainment.png (each algorithm's surfaces)."""
    sense = np.array(objective.senses)
    with (out / "attainment.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["algorithm", "percentile", *objective.indices])
        for algorithm, levels in surfaces.items():
            for percentile, points in levels.items():
                for point in points * sense:
                    writer.writerow([algorithm, f"{percentile:g}", *map(repr, map(float, point))])
    if len(objective.indices) == 2:
        plot_attainment({algorithm: {percentile: points * sense for percentile, points
                                     in levels.items()} for algorithm, levels in surfaces.items()},
                        objective.indices, out / "attainment.png")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
