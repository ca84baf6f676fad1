"""Swarm optimizers for tuning controller gains, ROS-free (numpy only).

One interface for every algorithm (see base.py for the details):

    result = optimize("bas-pso", fitness, lower, upper, budget=2000, seed=7,
                      x0=paper_gains, max_time=3600, stall_iterations=20,
                      population_size=30)

* fitness(X) takes a batch X of shape (n, d) and returns n values, lower is
  better; the whole population comes in one call, so the caller may evaluate
  it in parallel. NaN/inf values count as the worst.
* budget counts fitness evaluations (every probe included) and is never
  exceeded; seed (int or numpy Generator) makes the run reproducible, and the
  same seed with the same fitness values requests the same batches.
* Algorithm options (population_size, coefficients) go as keyword arguments;
  each algorithm's module documents its defaults (its paper's where the paper
  gives them) and every choice the paper leaves open.

Algorithms: "pso" (seed 000), "bas" and "bas-pso" (seed 000), "aw-pso"
(seed 001, per-particle adaptive inertia), "apso" (seed 003), "ga-pso" (seed 004), "wso"
(white shark, the improved shark optimizer seed 000 compares with), "kh" (krill herd, seed 002).
"""

from __future__ import annotations

from typing import Any

from .apso import AdaptivePSO
from .awpso import AdaptiveWeightPSO
from .bas import BeetleAntennaeSearch, BeetleSwarm
from .base import Fitness, IterationRecord, Optimizer, Result, Seed, StopReason
from .gapso import GeneticPSO
from .krill_herd import KrillHerd
from .pso import ParticleSwarm
from .wso import WhiteShark

ALGORITHMS: dict[str, type[Optimizer]] = {
    "pso": ParticleSwarm,
    "bas": BeetleAntennaeSearch,
    "bas-pso": BeetleSwarm,
    "apso": AdaptivePSO,
    "aw-pso": AdaptiveWeightPSO,
    "ga-pso": GeneticPSO,
    "wso": WhiteShark,
    "kh": KrillHerd,
}


def create(name: str, **options: Any) -> Optimizer:
    """The algorithm `name` with its options (e.g. population_size)."""
    try:
        algorithm = ALGORITHMS[name]
    except KeyError:
        raise ValueError(f"unknown optimizer {name!r}; known: {', '.join(ALGORITHMS)}") from None
    return algorithm(**options)


def optimize(name: str, fitness: Fitness, lower: Any, upper: Any, budget: int, seed: Seed, *,
             x0: Any = None, max_time: float | None = None, stall_iterations: int | None = None,
             stall_tolerance: float = 0.0, bounded: bool = False, **options: Any) -> Result:
    """Minimise `fitness` over the box [lower, upper] with the algorithm `name`
    (`bounded`: fitness(X, bounds), see base.py)."""
    return create(name, **options).minimize(
        fitness, lower, upper, budget, seed, x0=x0, max_time=max_time,
        stall_iterations=stall_iterations, stall_tolerance=stall_tolerance, bounded=bounded)


__all__ = ["ALGORITHMS", "AdaptivePSO", "AdaptiveWeightPSO", "BeetleAntennaeSearch", "BeetleSwarm",
           "GeneticPSO", "IterationRecord", "KrillHerd", "Optimizer", "ParticleSwarm", "Result",
           "StopReason", "WhiteShark", "create", "optimize"]
