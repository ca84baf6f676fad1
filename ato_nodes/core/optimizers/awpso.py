"""Adaptive-inertia PSO of seed 001 (the LSSVM model's hyperparameter search).

The PSO update of pso.py (eq. 11-12 of the paper) with an inertia weight per
particle, set every iteration from where the particle's current fitness lies in
the swarm's (eq. 13; the formula is an image in the source, so the standard
adaptive-weight form that matches its text is used):

    w_i = w_min + (w_max - w_min) (f_i - f_min) / (f_avg - f_min)   if f_i <= f_avg
    w_i = w_max                                                     otherwise

f_min and f_avg the minimum and mean of the swarm's current values: a particle
near the best exploits (small w), one worse than average explores (w_max). All
equal (f_avg = f_min): w_min for every particle. Non-finite values count as the
worst finite value.

Paper's settings (defaults): N = 40 particles, c1 = c2 = 2, w in [0.4, 0.9];
its M = 100 iterations are budget = 40 * 101. Where it is silent: initial swarm
uniform in the box (x0 first), velocity clamping and absorbing walls as the PSO.
"""

from __future__ import annotations

import numpy as np

from .base import Run, finite_or_worst
from .pso import VELOCITY_LIMIT, Swarm, SwarmOptimizer


def adaptive_inertia(values: np.ndarray, w_min: float, w_max: float) -> np.ndarray:
    """Eq. 13: one inertia weight per particle from its current fitness."""
    f = finite_or_worst(values)
    low, mean = f.min(), f.mean()
    if not mean > low:
        return np.full(len(f), w_min)
    return np.where(f <= mean, w_min + (w_max - w_min) * (f - low) / (mean - low), w_max)


class AdaptiveWeightPSO(SwarmOptimizer):
    name = "aw-pso"

    def __init__(self, population_size: int = 40, w_min: float = 0.4, w_max: float = 0.9,
                 c1: float = 2.0, c2: float = 2.0, velocity_limit: float = VELOCITY_LIMIT):
        super().__init__(population_size, velocity_limit)
        if not 0.0 <= w_min <= w_max:
            raise ValueError("need 0 <= w_min <= w_max")
        self.w_min, self.w_max, self.c1, self.c2 = w_min, w_max, c1, c2

    def _coefficients(self, run: Run, swarm: Swarm):
        weights = adaptive_inertia(swarm.f, self.w_min, self.w_max)
        return weights[:, None], self.c1, self.c2
