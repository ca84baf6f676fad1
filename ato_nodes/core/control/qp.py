"""A small dense quadratic program, by the dual active-set method of Goldfarb and
Idnani (1983), in plain loops that compile (ROS-free; no SciPy, no BLAS):

    minimise 1/2 x^T H x + g^T x   subject to   lower <= A x <= upper   (row by row),

H symmetric positive definite, a few variables (the GPC's control moves). It starts at
the unconstrained minimum -H^-1 g and adds the most violated constraint at a time,
dropping a held one whose multiplier would turn negative: every iterate is the optimum
for the constraints it holds, so it ends at the optimum of the whole after finitely
many steps, or finds the constraints inconsistent. Each step solves the working set's
system anew from the Cholesky factor L of H (cheaper than updating factors at this
size, and simpler): with N the held constraints' normals (rows), W = N L^-T, the added
normal n and w = L^-1 n,

    r = (W W^T)^-1 W w    how the held multipliers change per unit of the new one,
    z = L^-T (w - W^T r)  the primal direction that keeps the held constraints held.

A constraint is violated when beyond its bound by more than PRIMAL_TOLERANCE (relative
to the bound, at least 1); n lies in the held normals' span when |w - W^T r|^2 is at
most ZERO_TOLERANCE |w|^2 (a pure dual step then drops a held one).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable

PRIMAL_TOLERANCE = 1e-12
ZERO_TOLERANCE = 1e-14
SOLVED, INFEASIBLE, NOT_CONVEX, ITERATION_LIMIT = 1, -1, -2, -3


@jitable
def cholesky(matrix: np.ndarray, factor: np.ndarray, size: int) -> bool:
    """The lower Cholesky factor of matrix[:size, :size] into factor[:size, :size]; False
    if it is not (numerically) positive definite."""
    for j in range(size):
        pivot = matrix[j, j]
        for k in range(j):
            pivot -= factor[j, k] * factor[j, k]
        if not pivot > 0.0:
            return False
        factor[j, j] = math.sqrt(pivot)
        for i in range(j + 1, size):
            value = matrix[i, j]
            for k in range(j):
                value -= factor[i, k] * factor[j, k]
            factor[i, j] = value / factor[j, j]
        for i in range(j):
            factor[i, j] = 0.0
    return True


@jitable
def lower_solve(factor: np.ndarray, rhs: np.ndarray, solution: np.ndarray, size: int) -> None:
    """L y = rhs (the first `size` entries)."""
    for i in range(size):
        value = rhs[i]
        for k in range(i):
            value -= factor[i, k] * solution[k]
        solution[i] = value / factor[i, i]


@jitable
def upper_solve(factor: np.ndarray, rhs: np.ndarray, solution: np.ndarray, size: int) -> None:
    """L^T x = rhs (the first `size` entries)."""
    for i in range(size - 1, -1, -1):
        value = rhs[i]
        for k in range(i + 1, size):
            value -= factor[k, i] * solution[k]
        solution[i] = value / factor[i, i]


class Work(NamedTuple):
    """solve_qp's work space, for n variables."""

    factor: np.ndarray       # n x n, L
    held: np.ndarray         # n, the held constraints' rows
    sides: np.ndarray        # n, +1 the lower bound held, -1 the upper
    multipliers: np.ndarray  # n, theirs
    normal: np.ndarray       # n, the added constraint's
    w: np.ndarray            # n
    across: np.ndarray       # n x n, W
    gram: np.ndarray         # n x n, W W^T
    gram_factor: np.ndarray  # n x n
    r: np.ndarray            # n
    z: np.ndarray            # n
    middle: np.ndarray       # n


@jitable
def work_space(n: int) -> Work:
    return Work(np.zeros((n, n)), np.zeros(n, np.int64), np.zeros(n), np.zeros(n),
                np.zeros(n), np.zeros(n), np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n)),
                np.zeros(n), np.zeros(n), np.zeros(n))


@jitable
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    value = 0.0
    for i in range(len(a)):
        value += a[i] * b[i]
    return value


@jitable
def _set_normal(rows: np.ndarray, index: int, side: float, normal: np.ndarray) -> None:
    """The normal of row `index`'s held side: +A_i (lower <= A_i x) or -A_i (A_i x <=
    upper)."""
    for j in range(len(normal)):
        normal[j] = side * rows[index, j]


@jitable
def _most_violated(rows: np.ndarray, lower: np.ndarray, upper: np.ndarray, x: np.ndarray,
                   work: Work, count: int) -> tuple[int, float]:
    """(row, side) of the constraint x violates most among those not held; row -1: none
    beyond PRIMAL_TOLERANCE."""
    most, index, side = 0.0, -1, 0.0
    for i in range(len(lower)):
        if i in work.held[:count]:
            continue
        value = _dot(rows[i], x)
        below, above = lower[i] - value, value - upper[i]
        if below > PRIMAL_TOLERANCE * max(1.0, abs(lower[i])) and below > most:
            most, index, side = below, i, 1.0
        if above > PRIMAL_TOLERANCE * max(1.0, abs(upper[i])) and above > most:
            most, index, side = above, i, -1.0
    return index, side


@jitable
def _direction(rows: np.ndarray, work: Work, count: int) -> bool:
    """work.r and work.z for adding work.normal to the `count` held constraints (module
    docstring); False if the normal lies in the held normals' span (z is then 0)."""
    n, factor, across = len(work.normal), work.factor, work.across
    lower_solve(factor, work.normal, work.w, n)
    for j in range(count):
        _set_normal(rows, work.held[j], work.sides[j], work.middle)
        lower_solve(factor, work.middle, across[j], n)
    for i in range(count):
        for j in range(i + 1):
            work.gram[i, j] = work.gram[j, i] = _dot(across[i], across[j])
        work.middle[i] = _dot(across[i], work.w)
    if count > 0 and cholesky(work.gram, work.gram_factor, count):
        lower_solve(work.gram_factor, work.middle, work.z, count)
        upper_solve(work.gram_factor, work.z, work.r, count)
    elif count > 0:  # never: the held normals are independent (each added off their span)
        work.r[:count] = 0.0
    for k in range(n):
        value = work.w[k]
        for j in range(count):
            value -= across[j, k] * work.r[j]
        work.middle[k] = value
    upper_solve(factor, work.middle, work.z, n)
    spanned = _dot(work.middle, work.middle) <= ZERO_TOLERANCE * _dot(work.w, work.w)
    return count < n and not spanned


@jitable
def _dual_step(work: Work, count: int) -> tuple[float, int]:
    """(largest step before a held multiplier reaches 0, that constraint's place; inf
    and -1 if none decreases)."""
    step, place = math.inf, -1
    for j in range(count):
        if work.r[j] > 0.0 and work.multipliers[j] / work.r[j] < step:
            step, place = work.multipliers[j] / work.r[j], j
    return step, place


@jitable
def _drop(work: Work, count: int, place: int) -> int:
    for j in range(place, count - 1):
        work.held[j] = work.held[j + 1]
        work.sides[j] = work.sides[j + 1]
        work.multipliers[j] = work.multipliers[j + 1]
    return count - 1


@jitable
def _add(rows: np.ndarray, bound: float, x: np.ndarray, work: Work, count: int, index: int,
         side: float) -> int:
    """Steps towards holding constraint (index, side) at `bound` (its normal in
    work.normal), dropping held ones whose multiplier reaches 0 on the way: the new
    count of held constraints, -1 if the constraints are inconsistent."""
    added = 0.0
    while True:
        full = math.inf
        if _direction(rows, work, count):
            full = (bound - _dot(work.normal, x)) / _dot(work.z, work.normal)
        dual, place = _dual_step(work, count)
        if full == math.inf and dual == math.inf:
            return -1
        step = min(full, dual)
        if full < math.inf:
            for k in range(len(x)):
                x[k] += step * work.z[k]
        for j in range(count):
            work.multipliers[j] -= step * work.r[j]
        added += step
        if full <= dual:
            work.held[count], work.sides[count], work.multipliers[count] = index, side, added
            return count + 1
        count = _drop(work, count, place)


@jitable
def solve_qp(hessian: np.ndarray, gradient: np.ndarray, rows: np.ndarray, lower: np.ndarray,
             upper: np.ndarray, x: np.ndarray, work: Work) -> int:
    """The minimiser into x (module docstring; `work` from work_space(len(x))): SOLVED,
    or INFEASIBLE, NOT_CONVEX (H not positive definite), ITERATION_LIMIT."""
    n = len(x)
    if not cholesky(hessian, work.factor, n):
        return NOT_CONVEX
    for k in range(n):
        work.middle[k] = -gradient[k]
    lower_solve(work.factor, work.middle, work.w, n)
    upper_solve(work.factor, work.w, x, n)
    count = 0
    for _ in range(4 * (len(lower) + n) + 10):
        index, side = _most_violated(rows, lower, upper, x, work, count)
        if index < 0:
            return SOLVED
        _set_normal(rows, index, side, work.normal)
        count = _add(rows, lower[index] if side > 0.0 else -upper[index], x, work, count,
                     index, side)
        if count < 0:
            return INFEASIBLE
    return ITERATION_LIMIT
