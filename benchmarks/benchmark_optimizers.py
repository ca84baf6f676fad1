#!/usr/bin/env python3
"""Benchmark this project's optimizers against mealpy, pyswarms and niapy.

Every algorithm gets the same budget in fitness evaluations on sphere,
Rosenbrock, Rastrigin, Ackley and Griewank (standard bounds), in each
dimension asked for, over several seeds; the script prints one table of
median best values and a two-sided Mann-Whitney U test (p < 0.05, normal
approximation with tie correction, from scipy) for project PSO vs mealpy's
OriginalPSO, project PSO vs pyswarms' GlobalBestPSO and project KH vs niapy's
KrillHerd.

External libraries (benchmark-only, requirements-bench.txt), budgets made equal:
* mealpy OriginalPSO, its default coefficients (c1 = c2 = 2.05, w = 0.4) and
  the project PSO's population; it evaluates the initial population and then
  pop_size per epoch, so epochs = budget // pop_size - 1. Seeded by solve(seed=).
  Note that it keeps a particle's move only if it improves the particle
  (greedy selection), unlike the PSO of the papers.
* pyswarms GlobalBestPSO, the project PSO's population and coefficients
  (w = 0.7298, c1 = c2 = 1.49618, the usual constriction-equivalent setting;
  pyswarms has no defaults) and its default handling of velocity (no clamp)
  and bounds (periodic); one swarm evaluation per iteration, so iters =
  budget // n_particles. pyswarms cannot be seeded by argument: numpy's global
  RNG is seeded (np.random.seed) before each of its runs.
* niapy KrillHerd, its defaults (50 krill, as the project KH); Task(max_evals=budget).
The counted evaluations of every run are checked against the budget.

    python benchmarks/benchmark_optimizers.py                 # full run (~11 min, 2 cores)
    python benchmarks/benchmark_optimizers.py --quick         # smoke check
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import _cli  # noqa: F401  (puts the repository on sys.path)
from ato_nodes.core.optimizers import ALGORITHMS, optimize

Batch = Callable[[np.ndarray], np.ndarray]


def sphere(x: np.ndarray) -> np.ndarray:
    return np.sum(x * x, axis=1)


def rosenbrock(x: np.ndarray) -> np.ndarray:
    return np.sum(100.0 * (x[:, 1:] - x[:, :-1] ** 2) ** 2 + (1.0 - x[:, :-1]) ** 2, axis=1)


def rastrigin(x: np.ndarray) -> np.ndarray:
    return 10.0 * x.shape[1] + np.sum(x * x - 10.0 * np.cos(2.0 * np.pi * x), axis=1)


def ackley(x: np.ndarray) -> np.ndarray:
    d = x.shape[1]
    return (-20.0 * np.exp(-0.2 * np.sqrt(np.sum(x * x, axis=1) / d))
            - np.exp(np.sum(np.cos(2.0 * np.pi * x), axis=1) / d) + 20.0 + np.e)


def griewank(x: np.ndarray) -> np.ndarray:
    i = np.sqrt(np.arange(1, x.shape[1] + 1))
    return 1.0 + np.sum(x * x, axis=1) / 4000.0 - np.prod(np.cos(x / i), axis=1)


FUNCTIONS: dict[str, tuple[Batch, float]] = {  # name: (batch function, half-width of the box)
    "sphere": (sphere, 100.0),
    "rosenbrock": (rosenbrock, 30.0),
    "rastrigin": (rastrigin, 5.12),
    "ackley": (ackley, 32.768),
    "griewank": (griewank, 600.0),
}


@dataclass
class Problem:
    function: Batch
    dim: int
    bound: float
    budget: int
    seed: int
    evaluations: int = 0

    def batch(self, x: np.ndarray) -> np.ndarray:
        self.evaluations += len(x)
        return self.function(x)

    def single(self, x: np.ndarray) -> float:
        return float(self.batch(np.asarray(x, dtype=float)[None, :])[0])

    @property
    def lower(self) -> np.ndarray:
        return np.full(self.dim, -self.bound)

    @property
    def upper(self) -> np.ndarray:
        return np.full(self.dim, self.bound)


def run_project(name: str) -> Callable[[Problem], float]:
    return lambda p: optimize(name, p.batch, p.lower, p.upper, p.budget, p.seed).best_f


PSO_POPULATION = ALGORITHMS["pso"]().population_size


def run_mealpy_pso(p: Problem) -> float:
    from mealpy import FloatVar
    from mealpy.swarm_based.PSO import OriginalPSO
    model = OriginalPSO(epoch=p.budget // PSO_POPULATION - 1, pop_size=PSO_POPULATION)
    problem = {"bounds": FloatVar(lb=p.lower, ub=p.upper), "obj_func": p.single,
               "minmax": "min", "log_to": None}
    return float(model.solve(problem, seed=p.seed).target.fitness)


def run_pyswarms_gbest(p: Problem) -> float:
    import pyswarms
    np.random.seed(p.seed)  # pyswarms draws from numpy's global RNG only
    swarm = pyswarms.single.GlobalBestPSO(
        n_particles=PSO_POPULATION, dimensions=p.dim, bounds=(p.lower, p.upper),
        options={"c1": 1.49618, "c2": 1.49618, "w": 0.7298})
    cost, _ = swarm.optimize(p.batch, iters=p.budget // PSO_POPULATION, verbose=False)
    return float(cost)


def run_niapy_kh(p: Problem) -> float:
    from niapy.algorithms.basic import KrillHerd
    from niapy.problems import Problem as NiapyProblem
    from niapy.task import Task

    class Wrapped(NiapyProblem):
        def _evaluate(self, x):
            return p.single(x)

    task = Task(problem=Wrapped(p.dim, -p.bound, p.bound), max_evals=p.budget)
    return float(KrillHerd(seed=p.seed).run(task)[1])


RUNNERS: dict[str, Callable[[Problem], float]] = {
    **{name: run_project(name) for name in ALGORITHMS},
    "mealpy-PSO": run_mealpy_pso,
    "pyswarms-GBPSO": run_pyswarms_gbest,
    "niapy-KH": run_niapy_kh,
}
PAIRS = [("pso", "mealpy-PSO"), ("pso", "pyswarms-GBPSO"), ("kh", "niapy-KH")]


def mann_whitney(ours: np.ndarray, theirs: np.ndarray) -> tuple[str, float]:
    """'win' / 'loss' (ours lower / higher, p < 0.05) or 'tie', and p."""
    from scipy.stats import mannwhitneyu
    if np.all(ours == ours[0]) and np.all(theirs == ours[0]):
        return "tie", 1.0  # one value in both samples: no ranks to compare
    u, p = mannwhitneyu(ours, theirs, alternative="two-sided")
    if p >= 0.05:
        return "tie", float(p)
    return ("win" if u < len(ours) * len(theirs) / 2 else "loss"), float(p)


Table = tuple[str, list[str], list[list[str]]]  # title, header, rows
Results = dict[tuple[str, int, str], np.ndarray]  # (function, dim, algorithm): best values


def run_all(cases: list[tuple[str, int]], names: list[str], seeds: range,
            budget_per_dim: int) -> tuple[Results, dict[str, float], set[str]]:
    """Best values of every run, seconds per algorithm, algorithms that used
    less than the budget in some run."""
    results, seconds, short = {}, dict.fromkeys(names, 0.0), set()
    for function, dim in cases:
        batch, bound = FUNCTIONS[function]
        for name in names:
            values = []
            for seed in seeds:
                problem = Problem(batch, dim, bound, budget_per_dim * dim, seed)
                started = time.perf_counter()
                values.append(RUNNERS[name](problem))
                seconds[name] += time.perf_counter() - started
                if problem.evaluations > problem.budget:
                    raise SystemExit(f"{name} used {problem.evaluations} evaluations "
                                     f"of {problem.budget}")
                if problem.evaluations < problem.budget:
                    short.add(name)
            results[function, dim, name] = np.array(values)
        print(f"done {function} {dim}-D", flush=True)
    return results, seconds, short


def median_table(results: Results, cases: list[tuple[str, int]], names: list[str]) -> Table:
    rows = []
    for function, dim in cases:
        medians = [np.median(results[function, dim, name]) for name in names]
        rows.append([function, str(dim), *(f"{m:.3g}" for m in medians),
                     names[int(np.argmin(medians))]])
    return "Median best value", ["function", "d", *names, "lowest"], rows


def test_table(results: Results, cases: list[tuple[str, int]], names: list[str]) -> Table:
    pairs = [pair for pair in PAIRS if set(pair) <= set(names)]
    totals = {pair: {"win": 0, "tie": 0, "loss": 0} for pair in pairs}
    rows = []
    for function, dim in cases:
        cells = []
        for ours, theirs in pairs:
            outcome, p = mann_whitney(results[function, dim, ours], results[function, dim, theirs])
            totals[ours, theirs][outcome] += 1
            cells.append(f"{outcome} (p={p:.2g})")
        rows.append([function, str(dim), *cells])
    rows.append(["total", "", *(f"{t['win']}/{t['tie']}/{t['loss']}" for t in totals.values())])
    return ("Two-sided Mann-Whitney U at p < 0.05: win/tie/loss of the first named",
            ["function", "d", *(f"{ours} vs {theirs}" for ours, theirs in pairs)], rows)


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def plain_table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(row[i]) for row in [header, *rows]) for i in range(len(header))]
    return "\n".join("  ".join(cell.rjust(w) for cell, w in zip(row, widths, strict=False))
                     for row in [header, *rows])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="smoke check: 3 seeds, 100 evaluations per dimension, dimension 10")
    parser.add_argument("--dims", type=int, nargs="+", default=[10, 30])
    parser.add_argument("--seeds", type=int, default=10, help="runs per function and dimension")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--budget-per-dim", type=int, default=500,
                        help="evaluations per dimension (niapy's KH needs ~0.5 ms per "
                             "evaluation: 10000 x d would take hours)")
    parser.add_argument("--algorithms", nargs="+", choices=list(RUNNERS), default=list(RUNNERS))
    parser.add_argument("--out", help="also write the tables as Markdown to this file")
    args = parser.parse_args()
    if args.quick:
        args.seeds, args.budget_per_dim, args.dims = 3, 100, [10]
    logging.disable(logging.WARNING)  # mealpy and niapy log every run

    cases = [(function, dim) for dim in args.dims for function in FUNCTIONS]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    results, seconds, short = run_all(cases, args.algorithms, seeds, args.budget_per_dim)
    setting = (f"{args.seeds} seeds from {args.first_seed}, budget {args.budget_per_dim} x d "
               f"evaluations")
    tables = [median_table(results, cases, args.algorithms)]
    if any(set(pair) <= set(args.algorithms) for pair in PAIRS):
        tables.append(test_table(results, cases, args.algorithms))
    timing = ("Every run used exactly the budget. " if not short else
              f"Used less than the budget in some runs: {', '.join(sorted(short))}. ")
    timing += "Seconds per algorithm, all runs: " + ", ".join(
        f"{name} {seconds[name]:.0f}" for name in args.algorithms)

    print(f"\n{setting}")
    for title, header, rows in tables:
        print(f"\n{title}\n{plain_table(header, rows)}")
    print(f"\n{timing}")
    if args.out:
        with open(args.out, "w") as out:
            out.write(f"{setting}\n")
            for title, header, rows in tables:
                out.write(f"\n{title}\n\n{markdown_table(header, rows)}\n")
            out.write(f"\n{timing}\n")


if __name__ == "__main__":
    main()
