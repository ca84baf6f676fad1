"""GA-hybrid PSO of seed 004 (metro second-order ADRC tuning).

Each generation:
1. PSO move of the whole swarm (pso.py), inertia falling linearly from 0.93 to
   0.31 over the generations the budget allows; n evaluations.
2. Sort by current fitness. The best third (n // 3 particles) survives as is.
3. The middle third (n // 3) is replaced by children of the best third: two
   parents drawn uniformly (with replacement) from it, arithmetic crossover
   child = a p1 + (1 - a) p2 with a uniform in [0, 1] per gene, then mutation:
   each gene, with probability 1 / d, gets Gaussian noise of standard
   deviation 0.1 (upper - lower); clipped to the box.
4. The worst third (the rest) is re-initialised in randomly chosen dimensions:
   each dimension is redrawn uniformly in the box with probability 1 / 2, and
   at least one is.
5. The regenerated particles are evaluated (one batch, n - n // 3 evaluations)
   and personal bests updated. They start at rest (velocity zero); the
   personal best of their slot is kept.

So a generation costs n + (n - n // 3) evaluations. The patent gives the
thirds, the inertia range and the size (70 particles, 100 generations); the
operators' forms and rates above are this project's choices, as are
c1 = c2 = 2, the velocity clamping and the bounds (as the PSO).
"""

from __future__ import annotations

import numpy as np

from .base import Run
from .pso import VELOCITY_LIMIT, ParticleSwarm, Swarm, check_population


class GeneticPSO(ParticleSwarm):
    name = "ga-pso"
    own_best_bound = False  # its selection ranks the current values

    def __init__(self, population_size: int = 70, w_start: float = 0.93, w_end: float = 0.31,
                 c1: float = 2.0, c2: float = 2.0, velocity_limit: float = VELOCITY_LIMIT,
                 mutation_scale: float = 0.1, redraw_probability: float = 0.5):
        check_population(population_size, 3)
        super().__init__(population_size, w_start, w_end, c1, c2, velocity_limit)
        self.mutation_scale = mutation_scale
        self.redraw_probability = redraw_probability

    def evaluations_per_iteration(self) -> int:
        return 2 * self.population_size - self.population_size // 3

    def _step(self, run: Run, swarm: Swarm) -> None:
        super()._step(run, swarm)
        order = np.argsort(swarm.f, kind="stable")
        third = swarm.size // 3
        elite, middle, worst = order[:third], order[third:2 * third], order[2 * third:]
        rows = np.concatenate([middle, worst])
        x = np.vstack([self._children(run, swarm.x[elite], len(middle)),
                       self._partly_redrawn(run, swarm.x[worst])])
        swarm.v[rows] = 0.0
        swarm.place(rows, x, run.evaluate(x))

    def _children(self, run: Run, parents: np.ndarray, count: int) -> np.ndarray:
        first, second = run.rng.integers(0, len(parents), (2, count))
        a = run.rng.random((count, run.dim))
        children = a * parents[first] + (1.0 - a) * parents[second]
        mutated = run.rng.random(children.shape) < 1.0 / run.dim
        noise = run.rng.standard_normal(children.shape) * (self.mutation_scale * run.span)
        return run.clip(children + mutated * noise)

    def _partly_redrawn(self, run: Run, x: np.ndarray) -> np.ndarray:
        redraw = run.rng.random(x.shape) < self.redraw_probability
        redraw[np.arange(len(x)), run.rng.integers(0, run.dim, len(x))] = True
        return np.where(redraw, run.uniform(len(x)), x)
