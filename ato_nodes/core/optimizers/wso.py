"""White shark optimizer (Braik, Hammouri, Atwan, Al-Betar and Awadallah,
Knowledge-Based Systems 243 (2022) 108457) with a chaotic-opposition start:
the "improved shark optimization" that seed 000 compares against.

With k = 1..K the iteration (K the iterations the budget allows), w_i a
shark's position, v_i its velocity, w_gbest the best point so far and
w_best^nu the personal best of a randomly chosen shark nu_i:

Movement speed towards prey (eq. 4-8):
    v_i <- mu [v_i + p1 c1 (w_gbest - w_i) + p2 c2 (w_best^nu_i - w_i)]
    p1 = p_max + (p_max - p_min) exp(-(4 k / K)^2)
    p2 = p_min + (p_max - p_min) exp(-(4 k / K)^2)
    mu = 2 / |2 - tau - sqrt(tau^2 - 4 tau)|          (constriction)
  c1, c2 uniform in [0, 1] per shark and dimension; nu_i uniform over sharks.
Movement towards the optimal prey (eq. 9-13):
    w_i <- w_i . not(w_o) + u . a + l . b    if rand < mv
    w_i <- w_i + v_i / f                     otherwise
    a = w_i > u, b = w_i < l, w_o = a xor b,  f = f_min + (f_max - f_min) / (f_max + f_min)
    mv = 1 / (a0 + exp((K / 2 - k) / a1))
  The first branch only moves out-of-box coordinates onto the violated bound;
  since every shark here is kept inside the box, it leaves the shark in place.
Movement towards the best shark and fish-school behaviour (eq. 14-17), per
coordinate with probability S_s:
    w'_i = w_gbest + r1 D sgn(r2 - 0.5),  D = |rand (w_gbest - w_i)|
    w_i <- (w_i + w'_i) / (2 r3)
    S_s = |1 - exp(-a2 k / K)|
  r3 is drawn in (0, 1] (no division by zero); the result is clipped to the
  box. With the published a2 = 0.0005, S_s stays below 5e-4.
Parameters as published: p_min = 0.5, p_max = 1.5, tau = 4.125, f_min = 0.07,
f_max = 0.75, a0 = 6.25, a1 = 100, a2 = 0.0005. Population 30 (the paper's
benchmark size is not in this project's sources; 30 is the common default).

Choices where the paper is silent or that differ from it:
* Improvement: the initial population is a chaotic (logistic-map) population
  and its opposition, keeping the fitter half (sampling.py, 2 n evaluations)
  instead of a uniform random one; it spreads the first sharks more evenly and
  starts the search from the better of each opposite pair.
* Velocities start at zero (as the authors' reference code).
* Every shark is clipped into the box and evaluated each iteration (the
  authors' code skips the evaluation of sharks outside the box instead; clipping
  keeps every batch the same size). Velocities are not clamped: mu < 1 keeps
  them bounded.
"""

from __future__ import annotations

import math

import numpy as np

from .base import Optimizer, Run
from .pso import Swarm, check_population
from .sampling import chaotic_opposition_start


class WhiteShark(Optimizer):
    name = "wso"

    def __init__(self, population_size: int = 30, p_min: float = 0.5, p_max: float = 1.5,
                 tau: float = 4.125, f_min: float = 0.07, f_max: float = 0.75,
                 a0: float = 6.25, a1: float = 100.0, a2: float = 0.0005):
        self.population_size = check_population(population_size, 2)
        if tau <= 4:
            raise ValueError("tau must exceed 4 for the constriction factor to be real")
        self.p_min, self.p_max = p_min, p_max
        self.constriction = 2.0 / abs(2.0 - tau - math.sqrt(tau * tau - 4.0 * tau))
        self.wave_frequency = f_min + (f_max - f_min) / (f_max + f_min)
        self.a0, self.a1, self.a2 = a0, a1, a2

    def initial_evaluations(self) -> int:
        return 2 * self.population_size

    def evaluations_per_iteration(self) -> int:
        return self.population_size

    def _start(self, run: Run) -> Swarm:
        x, f = chaotic_opposition_start(run, self.population_size)
        return Swarm.at(x, f, np.zeros_like(x))

    def _step(self, run: Run, sharks: Swarm) -> None:
        k, total = run.iteration, run.planned_iterations
        n, rng = sharks.size, run.rng
        decay = math.exp(-(4.0 * k / total) ** 2)
        p1 = self.p_max + (self.p_max - self.p_min) * decay
        p2 = self.p_min + (self.p_max - self.p_min) * decay
        neighbour = rng.integers(0, n, n)
        c1, c2 = rng.random((2, n, run.dim))
        sharks.v = self.constriction * (sharks.v + p1 * c1 * (run.best_x - sharks.x)
                                        + p2 * c2 * (sharks.best_x[neighbour] - sharks.x))

        exponent = min((total / 2.0 - k) / self.a1, 700.0)  # long runs: e^x would overflow
        movement_chance = 1.0 / (self.a0 + math.exp(exponent))
        wavy = rng.random(n) >= movement_chance
        x = np.where(wavy[:, None], sharks.x + sharks.v / self.wave_frequency, sharks.x)

        smell = abs(1.0 - math.exp(-self.a2 * k / total))
        schooling = rng.random(x.shape) < smell
        r = rng.random((4, n, run.dim))
        distance = np.abs(r[0] * (run.best_x - x))
        towards_best = run.best_x + r[1] * distance * np.sign(r[2] - 0.5)
        x = np.where(schooling, (x + towards_best) / (2.0 * (1.0 - r[3])), x)

        x = run.clip(x)
        sharks.place(np.arange(n), x, run.evaluate(x))
