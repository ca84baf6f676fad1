"""Krill herd (Gandomi and Alavi, Commun. Nonlinear Sci. Numer. Simul. 17 (2012)
4831-4845), the optimizer of seed 002, with its crossover and (optional)
mutation operators.

Each krill i moves by dX_i/dt = N_i + F_i + D_i, X_i <- X_i + dt dX_i/dt:

Induced motion:   N_i = N_max alpha_i + w_n N_i_old,  alpha_i = alpha_local + alpha_target
    alpha_local  = sum over neighbours j of K_ij X_ij
    alpha_target = C_best K_i,best X_i,best,   C_best = 2 (rand + I / I_max)
    K_ij = (K_i - K_j) / (K_worst - K_best),   X_ij = (X_j - X_i) / (||X_j - X_i|| + eps)
    neighbours of i: krill closer than d_s,i = sum_j ||X_i - X_j|| / (5 N)
Foraging:         F_i = V_f beta_i + w_f F_i_old,  beta_i = beta_food + beta_best
    beta_food = C_food K_i,food X_i,food,   C_food = 2 (1 - I / I_max)
    X_food = sum_i X_i / K_i / sum_i 1 / K_i   (centre of the herd weighted by 1/fitness)
    beta_best = K_i,ibest X_i,ibest            (the krill's own best position)
Physical diffusion: D_i = D_max (1 - I / I_max) delta_i, delta_i uniform in [-1, 1]^d
Time step:        dt = C_t sum_j (UB_j - LB_j)
Crossover:        X_i,m <- X_r,m with probability Cr = 0.2 K_i,best, r another random krill
Mutation:         X_i,m <- X_gbest,m + mu (X_p,m - X_q,m) with probability Mu = 0.05 / K_i,best,
                  mu uniform in [0, 1], p and q random krill (off by default: the
                  paper's best variant, KH II, uses crossover only)
Inertia weights w_n = w_f fall linearly from 0.9 to 0.1, and N_max = 0.01,
V_f = 0.02, C_t = 0.5 as in the paper; D_max = 0.005 (paper: 0.002-0.010).
Population 50.

Choices where the paper is silent or that differ from it:
* Normalised coordinates: the motion is computed in the box scaled to the unit
  cube, so dt = C_t d. For a cubic box this is exactly the paper's
  dt = C_t sum(UB - LB) in x; for unequal ranges it keeps every parameter's
  step proportional to its range.
* K_best is the best value found so far and K_worst the worst of the current
  herd. Non-finite values count as the worst finite value (finite_or_worst).
* Food weights: 1 / (K_i - K_min + s) with s = K_min when K_min > 0 (exactly
  the paper's 1 / K_i) and a tiny s otherwise, so a zero or negative fitness
  does not divide by zero.
* The food position is evaluated with the next herd, in the same batch (one
  batch of N + 1 per iteration, so the caller can evaluate it in parallel):
  the food that attracts the herd at iteration I is the centre of the herd of
  iteration I - 1 (none at the first iteration). The paper evaluates it in
  between, which would cost a batch of one per iteration.
* Crossover takes the coordinates of another krill's new position; mutation
  acts after crossover. Positions are clipped to the box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Optimizer, Run, finite_or_worst
from .pso import Swarm, check_population

_EPS = 1e-12  # in unit-cube lengths: keeps unit vectors of coincident krill finite


@dataclass
class Herd(Swarm):
    """A swarm whose velocity v holds the induced motion N; plus the foraging
    motion F and the last food position evaluated."""

    foraging: np.ndarray | None = None  # set by KrillHerd._start
    food_x: np.ndarray | None = None
    food_f: float = np.inf


def _unit(run: Run, x: np.ndarray) -> np.ndarray:
    """x in unit-cube coordinates."""
    return (x - run.lower) / run.span


def _normalised(differences: np.ndarray, scale: float) -> np.ndarray:
    return differences / scale if scale > 0 else np.zeros_like(differences)


def _attraction(u: np.ndarray, values: np.ndarray, target_u: np.ndarray,
                target_values: np.ndarray | float, scale: float) -> np.ndarray:
    """K_i,target X_i,target for every krill (rows of u)."""
    offsets = target_u - u
    unit = offsets / (np.linalg.norm(offsets, axis=-1, keepdims=True) + _EPS)
    return _normalised(values - target_values, scale)[:, None] * unit


def _local_attraction(u: np.ndarray, values: np.ndarray, scale: float) -> np.ndarray:
    """alpha_local: the neighbours' pull (better neighbours attract, worse repel)."""
    offsets = u[None, :, :] - u[:, None, :]  # offsets[i, j] = u_j - u_i
    distances = np.linalg.norm(offsets, axis=2)
    sensing = distances.sum(axis=1) / (5 * len(u))
    neighbours = distances < sensing[:, None]
    np.fill_diagonal(neighbours, False)
    weights = neighbours * _normalised(values[:, None] - values[None, :], scale)
    return np.einsum("ij,ijk->ik", weights / (distances + _EPS), offsets)


def _food_centre(u: np.ndarray, values: np.ndarray) -> np.ndarray:
    low = values.min()
    shift = low if low > 0 else 1e-12 * (1.0 + (values.max() - low))
    weights = 1.0 / (values - low + shift)
    return weights @ u / weights.sum()


class KrillHerd(Optimizer):
    name = "kh"

    def __init__(self, population_size: int = 50, n_max: float = 0.01, v_f: float = 0.02,
                 d_max: float = 0.005, c_t: float = 0.5, inertia_start: float = 0.9,
                 inertia_end: float = 0.1, crossover: bool = True, mutation: bool = False):
        self.population_size = check_population(population_size, 2)
        self.n_max, self.v_f, self.d_max, self.c_t = n_max, v_f, d_max, c_t
        self.inertia_start, self.inertia_end = inertia_start, inertia_end
        self.crossover, self.mutation = crossover, mutation

    def initial_evaluations(self) -> int:
        return self.population_size

    def evaluations_per_iteration(self) -> int:
        return self.population_size + 1

    def _start(self, run: Run) -> Herd:
        x = run.initial_population(self.population_size)
        herd = Herd.at(x, run.evaluate(x), np.zeros_like(x))
        herd.foraging = np.zeros_like(x)
        return herd

    def _step(self, run: Run, herd: Herd) -> None:
        n, rng, progress = herd.size, run.rng, run.progress
        u, values = _unit(run, herd.x), finite_or_worst(herd.f)
        best_value = min(run.best_f, values.min())
        scale = values.max() - best_value
        inertia = self.inertia_start + (self.inertia_end - self.inertia_start) * progress

        to_best = _attraction(u, values, _unit(run, run.best_x), best_value, scale)
        induced = (self.n_max * (_local_attraction(u, values, scale)
                                 + 2.0 * (rng.random((n, 1)) + progress) * to_best)
                   + inertia * herd.v)
        own_best = np.minimum(values, herd.best_f)  # = values while no finite value is known
        beta = _attraction(u, values, _unit(run, herd.best_x), own_best, scale)
        if herd.food_x is not None:
            food_value = min(herd.food_f, values.max())  # a non-finite food ranks worst
            beta += 2.0 * (1.0 - progress) * _attraction(u, values, _unit(run, herd.food_x),
                                                          food_value, scale)
        foraging = self.v_f * beta + inertia * herd.foraging
        diffusion = self.d_max * (1.0 - progress) * rng.uniform(-1.0, 1.0, (n, run.dim))
        moved = u + self.c_t * run.dim * (induced + foraging + diffusion)

        rank = _normalised(values - best_value, scale)  # K_i,best in [0, 1]
        if self.crossover:
            partner = (np.arange(n) + rng.integers(1, n, n)) % n
            crossed = rng.random((n, run.dim)) < 0.2 * rank[:, None]
            moved = np.where(crossed, moved[partner], moved)
        if self.mutation:
            p, q = rng.integers(0, n, (2, n))
            rate = np.minimum(1.0, 0.05 / np.maximum(rank, _EPS))
            mutated = rng.random((n, run.dim)) < rate[:, None]
            mutant = _unit(run, run.best_x) + rng.random((n, 1)) * (moved[p] - moved[q])
            moved = np.where(mutated, mutant, moved)

        x = run.clip(run.lower + moved * run.span)
        food_x = run.clip(run.lower + _food_centre(u, values) * run.span)
        evaluated = run.evaluate(np.vstack([x, food_x]))
        herd.v, herd.foraging = induced, foraging
        herd.place(np.arange(n), x, evaluated[:n])
        herd.food_x, herd.food_f = food_x, evaluated[n]
