"""Sampling helpers shared by several algorithms.

Chaotic-opposition start (seed 003's adaptive PSO; also the improvement of the
white shark optimizer here): a chaotic population P from the logistic map
z_k+1 = 4 z_k (1 - z_k), one independent sequence per dimension running over
the particles, z_0 uniform in (0, 1), P = xmin + z (xmax - xmin); its opposition
Q = xmin + xmax - P. Both are evaluated in one batch (2 n evaluations) and the
fitter n of the 2 n points are kept (opposition-based learning as in
Rahnamayan et al.; the patent's "keep the fitter population" is read
point-wise, as that keeps every good point). x0, if given, replaces P's row 0.
"""

from __future__ import annotations

import numpy as np

from .base import Run


def random_unit_vectors(rng: np.random.Generator, n: int, dim: int) -> np.ndarray:
    """n directions uniform on the unit sphere (normalised Gaussian vectors)."""
    vectors = rng.standard_normal((n, dim))
    return vectors / np.linalg.norm(vectors, axis=1, keepdims=True)


def logistic_map_fractions(rng: np.random.Generator, n: int, dim: int) -> np.ndarray:
    """n x dim values in (0, 1) from the logistic map at r = 4 (fully chaotic)."""
    z = np.empty((n, dim))
    z[0] = rng.random(dim)
    for row in range(1, n):
        z[row] = 4.0 * z[row - 1] * (1.0 - z[row - 1])
    return z


def chaotic_opposition_start(run: Run, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The fitter n of a chaotic population and its opposition, with their
    fitness values (2 n evaluations, one batch)."""
    fractions = logistic_map_fractions(run.rng, n, run.dim)
    chaotic = run.with_start_point(run.clip(run.lower + fractions * run.span))
    opposite = run.clip(run.lower + run.upper - chaotic)  # clip: rounding at the edges
    candidates = np.vstack([chaotic, opposite])
    values = run.evaluate(candidates)
    keep = np.argsort(values, kind="stable")[:n]
    return candidates[keep], values[keep]
