"""Several objectives at once, ROS-free: pymoo's NSGA-II and NSGA-III over a box, hard
constraints feasibility first, and what a front is judged by (moocore's non-dominated
filter and hypervolume; the knee and pseudo-weights choice).

    result = minimize_pareto("nsga2", evaluate, lower, upper, budget=400, seed=1,
                             objectives=2, constraints=1, x0=start, population_size=20)

* evaluate(X) takes a generation X of shape (n, d) and returns (F, G): F (n, objectives),
  every objective minimised (negate one to maximise); G (n, constraints), a candidate
  feasible when every G <= 0. The whole generation comes in one call, so the caller may
  evaluate it in parallel and hand the results back in candidate order.
* Feasibility first (Deb's rules, pymoo's own): a feasible candidate beats every
  infeasible one; two infeasible ones compare by their summed violation, so no penalty
  constant scales the objectives.
* budget counts evaluations and is never exceeded: budget // population generations
  (population at most budget); seed makes the run reproducible, and the same seed with
  the same (F, G) asks the same generations (a resumed tuning replays its log).
* x0 (the scenario's own values) is the first candidate of the first generation, the
  rest drawn uniformly in the box from the seed.

pymoo over Optuna's NSGA-II sampler: its ask-a-generation interface is the batch the
project's evaluators already run (local processes, a Dask cluster, the stack), NSGA-III
comes with it, and its constraint handling is feasibility first without a penalty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

PARETO_ALGORITHMS = ("nsga2", "nsga3")
DEFAULT_POPULATION = 20  # candidates a generation (tune.py --population)
MEDIAN_ATTAINMENT = 50.0  # percent of the runs: the attainment surface comparisons measure

Evaluate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class ParetoResult:
    """Every evaluated candidate in the order asked: X (n, d), F (n, objectives, every
    one minimised), G (n, constraints), and the generation each belongs to."""

    algorithm: str
    X: np.ndarray
    F: np.ndarray
    G: np.ndarray
    generation: np.ndarray

    @property
    def feasible(self) -> np.ndarray:
        return np.all(self.G <= 0.0, axis=1)


def minimize_pareto(name: str, evaluate: Evaluate, lower, upper, budget: int, seed: int, *,
                    objectives: int, constraints: int, x0=None,
                    population_size: int = DEFAULT_POPULATION) -> ParetoResult:
    """Minimise the objectives evaluate gives over the box [lower, upper] with pymoo's
    `name` (nsga2, nsga3) within `budget` evaluations."""
    from pymoo.core.problem import Problem
    from pymoo.optimize import minimize

    if name not in PARETO_ALGORITHMS:
        raise ValueError(f"unknown multi-objective optimizer {name!r}; known: "
                         f"{', '.join(PARETO_ALGORITHMS)}")
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    population = max(min(population_size, budget), 2)
    asked: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    class Candidates(Problem):
        def _evaluate(self, X, out, *args, **kwargs):
            F, G = evaluate(np.asarray(X, dtype=float))
            asked.append((np.array(X, dtype=float), np.asarray(F, float), np.asarray(G, float)))
            out["F"], out["G"] = F, G

    problem = Candidates(n_var=len(lower), n_obj=objectives, n_ieq_constr=constraints,
                         xl=lower, xu=upper)
    rng = np.random.default_rng(seed)
    start = rng.uniform(lower, upper, size=(population, len(lower)))
    if x0 is not None:
        start[0] = np.clip(np.asarray(x0, dtype=float), lower, upper)
    minimize(problem, _algorithm(name, population, objectives, start),
             termination=("n_gen", max(budget // population, 1)), seed=seed, verbose=False)
    return ParetoResult(name, np.vstack([x for x, _, _ in asked]),
                        np.vstack([f for _, f, _ in asked]).reshape(-1, objectives),
                        np.vstack([g for _, _, g in asked]).reshape(-1, constraints),
                        np.concatenate([np.full(len(x), number)
                                        for number, (x, _, _) in enumerate(asked)]))


def _algorithm(name: str, population: int, objectives: int, start: np.ndarray):
    if name == "nsga2":
        from pymoo.algorithms.moo.nsga2 import NSGA2
        return NSGA2(pop_size=population, sampling=start)
    from pymoo.algorithms.moo.nsga3 import NSGA3
    from pymoo.util.ref_dirs import get_reference_directions
    partitions = 1  # as many reference directions as the population holds, at most
    while math.comb(partitions + objectives, objectives - 1) <= population:
        partitions += 1
    directions = get_reference_directions("das-dennis", objectives, n_partitions=partitions)
    return NSGA3(directions, pop_size=population, sampling=start)


def nondominated(F: np.ndarray) -> np.ndarray:
    """The rows of F (minimised) no other row dominates, as a mask; duplicates kept."""
    import moocore
    if len(F) == 0:
        return np.zeros(0, dtype=bool)
    return moocore.is_nondominated(F, keep_weakly=True)


def hypervolume(F: np.ndarray, reference: np.ndarray) -> float:
    """The volume F (minimised) dominates up to `reference` (moocore's; rows not strictly
    better than the reference in every objective add nothing)."""
    import moocore
    inside = F[np.all(F < reference, axis=1)] if len(F) else F
    return float(moocore.hypervolume(inside, ref=reference)) if len(inside) else 0.0


def attainment(fronts: list[np.ndarray], percentiles: tuple[float, ...]
               ) -> dict[float, np.ndarray]:
    """The empirical attainment surfaces of several runs' fronts (each minimised, a point
    a row): for each percentile p, the surface of the points at least p % of the runs
    attain (reach or dominate): 100 / runs the best any run reached, 50 the median
    run's, 100 what every run reached (moocore's eaf). A run without a front attains
    nothing, so counts against every percentile."""
    import moocore
    present = [front for front in fronts if len(front)]
    surfaces = {percentile: np.zeros((0, fronts[0].shape[1])) for percentile in percentiles}
    # moocore counts the runs it is given: a percentile of all runs is more of those
    share = len(fronts) / max(len(present), 1)
    wanted = {percentile: min(percentile * share, 100.0) for percentile in percentiles
              if present and percentile * share <= 100.0 + 1e-9}
    if not wanted:
        return surfaces
    sets = np.repeat(np.arange(1, len(present) + 1), [len(front) for front in present])
    surface = moocore.eaf(np.vstack(present), sets, percentiles=sorted(set(wanted.values())))
    for percentile, level in wanted.items():
        surfaces[percentile] = surface[np.isclose(surface[:, -1], level), :-1]
    return surfaces


def knee(front: np.ndarray) -> int:
    """The front's member nearest the ideal point once each objective is scaled from its
    best (0) to its worst (1) on the front: the compromise an engineer reads as the
    knee."""
    return int(np.argmin(np.linalg.norm(scaled(front, *span(front)), axis=1)))


def pseudo_weight_choice(front: np.ndarray, weights: np.ndarray) -> int:
    """The front's member whose pseudo-weights (its relative distance from the worst of
    each objective, summing to one) are nearest `weights` (Deb's; pymoo's PseudoWeights)."""
    from pymoo.mcdm.pseudo_weights import PseudoWeights
    ideal, nadir = span(front)
    weights = np.asarray(weights, dtype=float) / np.sum(weights)
    return int(PseudoWeights(weights, ideal=ideal, nadir=np.where(nadir > ideal, nadir,
                                                                  ideal + 1.0)).do(front))


def span(front: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ideal (best of each objective) and nadir (worst) of a front."""
    return front.min(axis=0), front.max(axis=0)


def scaled(F: np.ndarray, ideal: np.ndarray, nadir: np.ndarray) -> np.ndarray:
    """F with each objective 0 at the ideal and 1 at the nadir (an objective that does
    not vary on the front: 0)."""
    width = np.where(nadir > ideal, nadir - ideal, 1.0)
    return (F - ideal) / width
