"""Beetle antennae search (seed 000 eq. 16-20) and the BAS-PSO hybrid (eq. 21-23).

Sensing, shared by both: a random unit direction dir, antennae
x_l = x + d0 dir / 2 and x_r = x - d0 dir / 2, both evaluated; the move
-step dir sign(f(x_l) - f(x_r)) goes towards the antenna that smells better.

    BAS:     x <- x - step dir sign(f_l - f_r)
    BAS-PSO: w = w_start - (w_start - w_end) t / T
             v <- w v + c1 r1 (pbest - x) + c2 r2 (gbest - x) - c3 r3 step dir sign(f_l - f_r)
             x <- x + v

Choices where the paper is silent:
* Normalised coordinates: dir, step and d0 are measured in the box scaled to
  the unit cube (a unit move along dir is dir * (upper - lower) in x), so a
  step is the same fraction of every parameter's range whatever the units.
* dir is uniform on the unit sphere (a normalised Gaussian vector); the
  paper's rand(n,1) / ||rand(n,1)|| read with rand uniform in [0, 1] would only
  point into the positive orthant.
* Step schedule: step_t = step_start (step_end / step_start)^(t / T), i.e.
  step *= eta every iteration with eta chosen so that the step reaches
  step_end when the budget runs out (a fixed eta = 0.95 freezes the beetle
  after ~200 iterations whatever the budget). d0 = step / c, the paper's
  constant ratio c = step / d0, with c = 5.
* sign(f_l - f_r) is 0 when the antennae smell the same (e.g. both
  non-finite): no move. Antennae and positions are clipped into the box.
* BAS evaluates only the antennae, 2 evaluations per iteration: the beetle's
  own position does not enter its motion, and the antennae, d0 / 2 away,
  already sample its neighbourhood (the reported best is the best antenna).
  It starts at x0 if given, else uniform in the box. Steps 0.5 -> 1e-5.
* BAS-PSO: every particle senses with its own antennae every iteration (the 2 n
  antennae in one batch), then the swarm moves (n): 3 n evaluations per
  iteration. The paper gives w = 0.6 and c1 = c2 = 2 next to the decreasing
  inertia of eq. 21; here w goes 0.8 -> 0.4 (mean 0.6). c3 = 1 and r3 uniform
  per particle and dimension (not given). Steps 0.1 -> 1e-5 (the push is
  clamped with the velocity anyway). Population, velocity clamping, bounds and
  initial swarm as the PSO (pso.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Optimizer, Run
from .pso import VELOCITY_LIMIT, ParticleSwarm, Swarm
from .sampling import random_unit_vectors


@dataclass(frozen=True)
class Antennae:
    step_start: float
    step_end: float
    step_to_d0: float = 5.0

    def __post_init__(self):
        if not (self.step_start > 0 and self.step_end > 0 and self.step_to_d0 > 0):
            raise ValueError("step_start, step_end and step_to_d0 must be positive")

    def step(self, progress: float) -> float:
        return self.step_start * (self.step_end / self.step_start) ** progress

    def smell_moves(self, run: Run, centres: np.ndarray) -> np.ndarray:
        """-step dir sign(f_l - f_r) for each row of `centres`, in x units; the
        2 n antennae are evaluated in one batch."""
        step = self.step(run.progress)
        directions = random_unit_vectors(run.rng, len(centres), run.dim) * run.span
        half_d0 = 0.5 * step / self.step_to_d0 * directions
        antennae = np.vstack([run.clip(centres + half_d0), run.clip(centres - half_d0)])
        values = run.evaluate(antennae)
        left, right = values[:len(centres)], values[len(centres):]
        sign = (left > right).astype(float) - (left < right)  # no NaN from inf - inf
        return -step * directions * sign[:, None]


class BeetleAntennaeSearch(Optimizer):
    name = "bas"

    def __init__(self, step_start: float = 0.5, step_end: float = 1e-5, step_to_d0: float = 5.0):
        self.antennae = Antennae(step_start, step_end, step_to_d0)

    def initial_evaluations(self) -> int:
        return 2

    def evaluations_per_iteration(self) -> int:
        return 2

    def _start(self, run: Run) -> np.ndarray:
        beetle = run.initial_population(1)
        self._step(run, beetle)  # the first sensing is the initialisation's evaluation
        return beetle

    def _step(self, run: Run, beetle: np.ndarray) -> None:
        beetle[:] = run.clip(beetle + self.antennae.smell_moves(run, beetle))


class BeetleSwarm(ParticleSwarm):
    name = "bas-pso"

    def __init__(self, population_size: int = 40, w_start: float = 0.8, w_end: float = 0.4,
                 c1: float = 2.0, c2: float = 2.0, c3: float = 1.0,
                 velocity_limit: float = VELOCITY_LIMIT,
                 step_start: float = 0.1, step_end: float = 1e-5, step_to_d0: float = 5.0):
        super().__init__(population_size, w_start, w_end, c1, c2, velocity_limit)
        self.c3 = c3
        self.antennae = Antennae(step_start, step_end, step_to_d0)

    def evaluations_per_iteration(self) -> int:
        return 3 * self.population_size

    def _step(self, run: Run, swarm: Swarm) -> None:
        moves = self.antennae.smell_moves(run, swarm.x)
        push = self.c3 * run.rng.random(moves.shape) * moves
        self._fly(run, swarm, *self._coefficients(run, swarm), push=push)
