"""Least-squares support vector regression of a train's NARX speed map (seed 001), ROS-free.

The map, one control period h ahead, with speeds y (m/s, measured) and commands u (N/kN):

    y(k) = y(k-1) + g(x(k)),   x(k) = [y(k-1) .. y(k-na), u(k-1-nk) .. u(k-nb-nk)]

na speed lags, nb command lags, nk whole periods of input delay (the train's dead
time). The paper writes y(k) = f(y(k-1), u(k-1)) (na = nb = 1, nk = 0); learning the
increment g = f - y(k-1) is the same map, with a target a thousand times smaller
than the speed range, so the kernel's length scale serves the dynamics, not the
identity. Regressors are scaled to [0, 1] over the identification data (speed
columns together, command columns together) before the kernel sees them.

LSSVM (Suykens): with the RBF kernel K(x, x') = exp(-|x - x'|^2 / (2 delta^2)) and
regularisation mu, the coefficients solve

    [0   1^T          ] [b    ]   [0]
    [1   Omega + I/mu ] [alpha] = [t],      Omega_ij = K(x_i, x_j)

solved here through the Cholesky factor L of H = Omega + I/mu (H eta = 1,
H nu = t, b = 1^T nu / 1^T eta, alpha = nu - b eta): no inverse, no pinv. The
triangular solves are the loops below, compiled: their sums run in a fixed order, so
a model's bits depend on its numbers alone, not on a BLAS library or its threads
(a node and simulate() agree on any machine), and the forward half L^-1 [1, t] is
kept: a new sample extends it by one row.

Online correction (`add`): a new sample is appended to the factor (one
triangular solve for its row, O(n^2), then the back substitution for the
coefficients, O(n^2)), never refactorised. The Schur complement of the new
row, d^2 = 1/mu + 1 - |L^-1 beta|^2, is guarded: below GUARD (relative) the
sample is numerically a copy of the dictionary and is rejected. The dictionary
is bounded: the identification samples stay, corrections fill a window of
`window` samples, and when it is full the oldest correction leaves (a rank-1
update of the factor's trailing block, the corrections' part, O(window^2)).
"""

from __future__ import annotations

import copy
import functools
import hashlib
import io
import json
import math
import os
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
from ..base import yamlfile
from ..base.errors import ScenarioError
from ..base.kernels import compiled, jitable

GUARD = 1e-10  # relative Schur complement below which a new sample is rejected
FORMAT = "ato-lssvm-1"


@dataclass(frozen=True)
class Layout:
    """The regressor: speed lags, command lags, input delay (whole periods)."""

    speed_lags: int = 1
    command_lags: int = 1
    delay: int = 0

    def __post_init__(self):
        if self.speed_lags < 1 or self.command_lags < 1 or self.delay < 0:
            raise ValueError("a regressor needs >= 1 speed lag, >= 1 command lag and a delay "
                             ">= 0")

    @property
    def size(self) -> int:
        return self.speed_lags + self.command_lags

    @property
    def history(self) -> int:
        """Past commands a regressor needs (the newest is u(k-1))."""
        return self.delay + self.command_lags

    def samples(self, speeds: np.ndarray, commands: np.ndarray,
                steps: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(regressors x(k), increments y(k) - y(k-1)) of a recorded run, for the steps k
        given (default: every step with a full history)."""
        first = max(self.speed_lags, self.history)
        if steps is None:
            steps = np.arange(first, len(speeds))
        steps = np.asarray(steps)
        if len(steps) and (steps.min() < first or steps.max() >= len(speeds)):
            raise ValueError("a sample step lacks its history")
        columns = [speeds[steps - j] for j in range(1, self.speed_lags + 1)]
        columns += [commands[steps - self.delay - j] for j in range(1, self.command_lags + 1)]
        return np.column_stack(columns), speeds[steps] - speeds[steps - 1]

    def regressor(self, speeds, commands) -> np.ndarray:
        """x(k) from histories, newest last: speeds ending with y(k-1), commands with
        u(k-1)."""
        ys = [speeds[-j] for j in range(1, self.speed_lags + 1)]
        us = [commands[-self.delay - j] for j in range(1, self.command_lags + 1)]
        return np.array(ys + us)


@jitable
def _rbf_exponents(z: np.ndarray, support: np.ndarray, width: float, difference: np.ndarray,
                   exponent: np.ndarray) -> None:
    """In place, row by row: difference = z - support and exponent = -|difference|^2 /
    width, the squares summed as np.einsum("ij,ij->i") sums them, to the bit: numpy's
    x86-64 baseline kernel (SSE2) keeps two lanes, lane l the columns l, l+2, ..; per
    block of eight columns it adds each lane's four products last-first, past the blocks
    one product per lane at a time, then lane 0 + lane 1 (tests/test_lssvm.py checks it
    against np.einsum): one pass instead of two numpy calls looping over rows of a few
    columns, and a fixed order of sums (einsum's own), whatever the machine."""
    count = len(z)
    blocks = count - count % 8
    for i in range(len(exponent)):
        for j in range(count):
            difference[i, j] = z[j] - support[i, j]
        even = odd = 0.0  # the lanes
        for start in range(0, blocks, 8):
            for j in range(start + 6, start - 1, -2):
                even = difference[i, j] * difference[i, j] + even
                odd = difference[i, j + 1] * difference[i, j + 1] + odd
        for j in range(blocks, count):
            if j % 2 == 0:
                even = difference[i, j] * difference[i, j] + even
            else:
                odd = difference[i, j] * difference[i, j] + odd
        exponent[i] = -(even + odd) / width


@jitable
def _dot(a: np.ndarray, b: np.ndarray, count: int) -> float:
    """a[:count] . b[:count] in four lanes (lane l the entries l, l+4, ..), then the
    lanes pairwise: a fixed order of sums that keeps the multiplier busy."""
    lane0 = lane1 = lane2 = lane3 = 0.0
    blocks = count - count % 4
    for j in range(0, blocks, 4):
        lane0 += a[j] * b[j]
        lane1 += a[j + 1] * b[j + 1]
        lane2 += a[j + 2] * b[j + 2]
        lane3 += a[j + 3] * b[j + 3]
    for j in range(blocks, count):
        lane0 += a[j] * b[j]
    return (lane0 + lane1) + (lane2 + lane3)


@jitable
def _forward_substitution(factor: np.ndarray, rhs: np.ndarray, solution: np.ndarray,
                          start: int, stop: int) -> None:
    """Rows start .. stop-1 of L y = rhs into `solution` (whose rows before `start`
    already hold y): row by row, each a dot product with the solved part."""
    for i in range(start, stop):
        solution[i] = (rhs[i] - _dot(factor[i], solution, i)) / factor[i, i]


@jitable
def _back_substitution(factor: np.ndarray, first: np.ndarray, second: np.ndarray,
                       count: int) -> None:
    """In place, L^T x = y for two vectors (y in, x out), L's rows read whole (the
    buffer is C-ordered): each solved entry is taken off the entries above it."""
    for j in range(count - 1, -1, -1):
        first[j] /= factor[j, j]
        second[j] /= factor[j, j]
        row, x1, x2 = factor[j], first[j], second[j]
        for i in range(j):
            first[i] -= x1 * row[i]
            second[i] -= x2 * row[i]


@jitable
def _squared_norm(a: np.ndarray, count: int) -> float:
    return _dot(a, a, count)


class Dictionary(NamedTuple):
    """An LSSVM in fixed-capacity arrays (capacity: the identification samples plus the
    correction window), what linearise_dictionary reads and add_sample changes: the
    arrays in place, the scalars in the tuple it returns. The LSSVM below and the GPC's
    compiled step (core/control/gpc_steps.py) run the same functions on it."""

    mu: float
    delta: float
    offset: np.ndarray      # regressor scaling, per column
    scale: np.ndarray
    fixed: int              # identification samples: they stay
    z: np.ndarray           # capacity x columns, scaled regressors
    t: np.ndarray           # increments, m/s (0 beyond size)
    # The lower Cholesky factor of H, padded with the identity beyond `size`: the
    # solves then run on the whole (contiguous) buffer, never on a copied slice.
    factor: np.ndarray
    ones: np.ndarray
    forward: np.ndarray     # 2 x capacity: L^-1 [1, t], the forward half of the solve
    row: np.ndarray         # a new sample's row of the factor
    difference: np.ndarray  # capacity x columns: z minus the dictionary (work space)
    weights: np.ndarray     # capacity: kernel values times alpha (work space)
    alpha: np.ndarray       # capacity: the coefficients (0 beyond size)
    solved: np.ndarray      # 2 x capacity: eta and nu of the back substitution
    size: int
    bias: float
    added: int
    rejected: int
    forgotten: int


def empty_dictionary(columns: int) -> Dictionary:
    """A Dictionary of no samples and no room: what the GPC's predictions without an
    LSSVM carry (one compiled step serves them all)."""
    return Dictionary(1.0, 1.0, np.zeros(columns), np.ones(columns), 0,
                      np.zeros((0, columns)), np.zeros(0), np.zeros((0, 0)), np.zeros(0),
                      np.zeros((2, 0)), np.zeros(0), np.zeros((0, columns)), np.zeros(0),
                      np.zeros(0), np.zeros((2, 0)), 0, 0.0, 0, 0, 0)


@jitable
def _counted(d: Dictionary, size: int, bias: float, added: int, rejected: int, forgotten: int
             ) -> Dictionary:
    """`d` with these scalars (compiled code has no NamedTuple._replace)."""
    return Dictionary(d.mu, d.delta, d.offset, d.scale, d.fixed, d.z, d.t, d.factor, d.ones,
                      d.forward, d.row, d.difference, d.weights, d.alpha, d.solved, size, bias,
                      added, rejected, forgotten)


@jitable
def _forward_rows(d: Dictionary, start: int) -> None:
    """L^-1 [1, t] from row `start` on (the rows before it are solved)."""
    _forward_substitution(d.factor, d.ones, d.forward[0], start, d.size)
    _forward_substitution(d.factor, d.t, d.forward[1], start, d.size)


@jitable
def _solved(d: Dictionary) -> Dictionary:
    """The coefficients from the forward half: eta = L^-T L^-1 1, nu = L^-T L^-1 t."""
    n = d.size
    eta, nu = d.solved[0], d.solved[1]
    eta[:n], nu[:n] = d.forward[0, :n], d.forward[1, :n]
    _back_substitution(d.factor, eta, nu, n)
    return _coefficients(d)


@jitable
def _coefficients(d: Dictionary) -> Dictionary:
    """b = 1^T nu / 1^T eta, alpha = nu - b eta, from d.solved's eta and nu."""
    n, eta, nu = d.size, d.solved[0], d.solved[1]
    bias = nu[:n].sum() / eta[:n].sum()
    for i in range(n):
        d.alpha[i] = nu[i] - bias * eta[i]
    return _counted(d, d.size, bias, d.added, d.rejected, d.forgotten)


@jitable
def _solved_with_row(d: Dictionary) -> Dictionary:
    """_solved after the factor gained its last row [l^T, s] (l in d.row): with
    u = L^-T l (one back substitution, not two), x = L'^-T y' is
    [x_old - (y_n / s) u, y_n / s] for each of eta and nu."""
    n = d.size - 1
    u, scale = d.row, d.factor[n, n]
    for j in range(n - 1, -1, -1):  # L^T u = l, in place, as _back_substitution
        u[j] /= d.factor[j, j]
        row, x = d.factor[j], u[j]
        for i in range(j):
            u[i] -= x * row[i]
    for k in range(2):
        last = d.forward[k, n] / scale
        for i in range(n):
            d.solved[k, i] -= last * u[i]
        d.solved[k, n] = last
    return _coefficients(d)


@jitable(inline=True)
def _kernel_terms(d: Dictionary, x: np.ndarray) -> None:
    """d.difference = z - the dictionary, d.weights = the kernel values at x (unscaled)."""
    n = d.size
    z = (x - d.offset) / d.scale
    _rbf_exponents(z, d.z[:n], 2.0 * d.delta ** 2, d.difference[:n], d.weights[:n])
    for i in range(n):
        d.weights[i] = math.exp(d.weights[i])


@jitable(inline=True)
def _linearise_dictionary(d: Dictionary, x: np.ndarray, gradient: np.ndarray) -> float:
    """g(x) at one unscaled regressor, its analytic gradient dg/dx into `gradient`: the
    RBF expansion's, sums in a fixed order (a model's bits are its numbers')."""
    n, columns = d.size, len(x)
    _kernel_terms(d, x)
    value = 0.0
    for j in range(columns):
        gradient[j] = 0.0
    for i in range(n):
        weight = d.alpha[i] * d.weights[i]
        value += weight
        for j in range(columns):
            gradient[j] += weight * d.difference[i, j]
    squared = d.delta ** 2
    for j in range(columns):
        gradient[j] = -gradient[j] / squared / d.scale[j]
    return value + d.bias


@jitable
def _add_sample(d: Dictionary, x: np.ndarray, target: float) -> tuple[Dictionary, bool]:
    """One more sample (unscaled regressor x, increment target): appended to the factor
    (one triangular solve for its row), the coefficients solved anew; False if the
    Schur-complement guard rejected it. The oldest correction leaves a full window."""
    capacity = len(d.t)
    if capacity == d.fixed:  # no window
        return d, False
    full = d.size == capacity
    if full:
        d = _forget_oldest_correction(d)
    n = d.size
    _kernel_terms(d, x)
    _forward_substitution(d.factor, d.weights, d.row, 0, n)
    pivot = 1.0 + 1.0 / d.mu
    schur = pivot - _squared_norm(d.row, n)
    if not schur > GUARD * pivot:
        return _counted(d, d.size, d.bias, d.added, d.rejected + 1, d.forgotten), False
    d.factor[n, :n] = d.row[:n]
    d.factor[n, n] = math.sqrt(schur)
    d.z[n] = (x - d.offset) / d.scale
    d.t[n] = target
    d = _counted(d, n + 1, d.bias, d.added + 1, d.rejected, d.forgotten)
    _forward_rows(d, n)
    return (_solved(d) if full else _solved_with_row(d)), True


@jitable
def _forget_oldest_correction(d: Dictionary) -> Dictionary:
    """Drop row/column `fixed` of H: the trailing block's factor becomes
    chol(L22 L22^T + l l^T), l the dropped column below it (rank-1 update), in place
    (the block moves up and left by one as it is updated)."""
    i, n, factor = d.fixed, d.size, d.factor
    column = factor[i + 1:n, i].copy()
    for j in range(n - i - 1):  # the classic rank-1 Cholesky update
        diagonal = factor[i + 1 + j, i + 1 + j]
        r = math.hypot(diagonal, column[j])
        c, s = r / diagonal, column[j] / diagonal
        factor[i + j, i + j] = r
        for k in range(j + 1, n - i - 1):
            updated = (factor[i + 1 + k, i + 1 + j] + s * column[k]) / c
            column[k] = c * column[k] - s * updated
            factor[i + k, i + j] = updated
    for k in range(i, n - 1):
        factor[k, :i] = factor[k + 1, :i]
        d.z[k] = d.z[k + 1]
        d.t[k] = d.t[k + 1]
    factor[n - 1, :] = 0.0
    factor[n - 1, n - 1] = 1.0
    d.z[n - 1] = 0.0
    d.t[n - 1] = 0.0
    d.alpha[n - 1] = 0.0
    d = _counted(d, n - 1, d.bias, d.added, d.rejected, d.forgotten + 1)
    _forward_rows(d, i)  # the rows from the dropped one on moved
    return d


# plain loops, slow in Python: from Python these, compiled whenever numba is installed
forward_rows = compiled(_forward_rows) or _forward_rows
solved = compiled(_solved) or _solved
linearise_dictionary = compiled(_linearise_dictionary) or _linearise_dictionary
add_sample = compiled(_add_sample) or _add_sample


class LSSVM:
    """The fitted regression g(x) with its factor, ready for prediction, its gradient
    (the GPC's linearisation) and online correction: a Dictionary and its functions."""

    def __init__(self, layout: Layout, mu: float, delta: float, offset: np.ndarray,
                 scale: np.ndarray, regressors: np.ndarray, targets: np.ndarray,
                 window: int = 0):
        if not (mu > 0 and math.isfinite(mu) and delta > 0 and math.isfinite(delta)):
            raise ValueError("mu and delta must be positive and finite")
        self.layout, self.mu, self.delta = layout, float(mu), float(delta)
        self.offset, self.scale = np.asarray(offset, float), np.asarray(scale, float)
        self.fixed = len(targets)
        self.window = window
        capacity = self.fixed + window
        z, t = np.zeros((capacity, layout.size)), np.zeros(capacity)
        z[:self.fixed], t[:self.fixed] = self.to_unit(np.asarray(regressors, float)), targets
        factor = np.eye(capacity)
        gram = self._kernel(z[:self.fixed], z[:self.fixed]) + np.eye(self.fixed) / self.mu
        try:
            factor[:self.fixed, :self.fixed] = np.linalg.cholesky(gram)
        except np.linalg.LinAlgError:
            raise ValueError(f"the kernel matrix is numerically singular for mu = {mu:g}, "
                             f"delta = {delta:g}") from None
        if not np.all(np.diag(factor)[:self.fixed] ** 2 > GUARD / self.mu):
            raise ValueError(f"the kernel matrix is numerically singular for mu = {mu:g}, "
                             f"delta = {delta:g}")
        d = Dictionary(self.mu, self.delta, self.offset, self.scale, self.fixed, z, t, factor,
                       np.ones(capacity), np.zeros((2, capacity)), np.empty(capacity),
                       np.empty((capacity, layout.size)), np.empty(capacity),
                       np.zeros(capacity), np.zeros((2, capacity)), self.fixed, 0.0, 0, 0, 0)
        forward_rows(d, 0)
        self.dictionary = solved(d)

    # The kernel in scaled coordinates ------------------------------------------
    def to_unit(self, x: np.ndarray) -> np.ndarray:
        return (x - self.offset) / self.scale

    def _kernel(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        distance = (np.sum(a * a, axis=1)[:, None] + np.sum(b * b, axis=1)[None, :]
                    - 2.0 * a @ b.T)
        return np.exp(-np.maximum(distance, 0.0) / (2.0 * self.delta ** 2))

    # The dictionary's figures -----------------------------------------------------
    @property
    def size(self) -> int:
        return self.dictionary.size

    @property
    def bias(self) -> float:
        return self.dictionary.bias

    @property
    def alpha(self) -> np.ndarray:
        return self.dictionary.alpha[:self.size]

    @property
    def added(self) -> int:
        return self.dictionary.added

    @property
    def rejected(self) -> int:
        return self.dictionary.rejected

    @property
    def forgotten(self) -> int:
        return self.dictionary.forgotten

    @property
    def support(self) -> np.ndarray:
        """The dictionary's regressors, scaled."""
        return self.dictionary.z[:self.size]

    # Prediction ---------------------------------------------------------------
    def increment(self, x: np.ndarray) -> np.ndarray:
        """g at each row of x (unscaled regressors), m/s."""
        z = self.to_unit(np.atleast_2d(x))
        return self._kernel(z, self.support) @ self.alpha + self.bias

    def linearise(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """(g(x), dg/dx) at one unscaled regressor."""
        gradient = np.empty(self.layout.size)
        value = linearise_dictionary(self.dictionary, np.asarray(x, float), gradient)
        return value, gradient

    # Online correction ----------------------------------------------------------
    def add(self, x: np.ndarray, target: float) -> bool:
        """Take one more sample (unscaled regressor x, increment target): True if it
        joined the dictionary, False if the Schur-complement guard rejected it (or the
        model has no window)."""
        self.dictionary, accepted = add_sample(self.dictionary, np.asarray(x, float),
                                               float(target))
        return bool(accepted)

    @property
    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """(unscaled regressors, increments) of the dictionary."""
        return self.support * self.scale + self.offset, self.dictionary.t[:self.size].copy()

    def with_window(self, window: int) -> LSSVM:
        """A fresh solve on the current dictionary, its samples all fixed, with room
        for `window` corrections (window 0: the reference the online updates are
        checked against)."""
        return LSSVM(self.layout, self.mu, self.delta, self.offset, self.scale, *self.samples,
                     window)

    def refit(self) -> LSSVM:
        return self.with_window(0)


def warm() -> None:
    """Compile the solves now (or load them from numba's cache): a tiny fit, one
    correction and one linearisation."""
    regressors = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, -0.5]])
    model = fit(Layout(), regressors, np.zeros(3), 10.0, 1.0, window=1)
    model.add(np.array([1.5, 1.0]), 0.1)
    model.linearise(np.array([1.0, 0.0]))


def unit_scaling(layout: Layout, regressors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(offset, scale) mapping the identification data's speeds, and its commands, to
    [0, 1] (one range per kind of column, so lags keep their relation)."""
    na = layout.speed_lags
    offset, scale = np.empty(layout.size), np.empty(layout.size)
    for columns in (slice(0, na), slice(na, layout.size)):
        low, high = float(regressors[:, columns].min()), float(regressors[:, columns].max())
        offset[columns], scale[columns] = low, max(high - low, 1e-9)
    return offset, scale


def fit(layout: Layout, regressors: np.ndarray, targets: np.ndarray, mu: float,
        delta: float, window: int = 0) -> LSSVM:
    offset, scale = unit_scaling(layout, regressors)
    return LSSVM(layout, mu, delta, offset, scale, regressors, targets, window)


# The model file ---------------------------------------------------------------
@dataclass(frozen=True)
class ModelFile:
    """What a `.npz` model file holds (FORMAT, one array per field):

    format           "ato-lssvm-1"
    layout           [na, nb, nk]
    mu, delta        hyperparameters (scaled coordinates)
    offset, scale    regressor scaling, one per regressor column
    regressors       identification samples x(k), unscaled (m/s, N/kN), n x (na + nb)
    targets          their increments y(k) - y(k-1), m/s
    alpha, bias      the solved coefficients (checked against a fresh solve on load)
    period           the control period the samples were taken at, s
    train            JSON: the plant.train preset name and its plant.* values
    arx              optional linear multi-model: centres (m/s), width (m/s) and one row
                     per centre [c, a_1..a_na, b_1..b_nb] of y(k) = c + sum a y + sum b u
    """

    lssvm: LSSVM
    period: float
    train: dict
    arx_centres: np.ndarray
    arx_width: float
    arx_coefficients: np.ndarray

    def save(self, path) -> None:
        """Written to a temporary file, then renamed over `path`: a reader sees the old
        model or the new one, never half of one."""
        model = self.lssvm
        path = Path(path)
        partial = path.with_name(f".{path.name}.partial")
        regressors, targets = model.samples
        with open(partial, "wb") as handle:
            np.savez(handle, format=FORMAT,
                     layout=np.array([model.layout.speed_lags, model.layout.command_lags,
                                      model.layout.delay]),
                     mu=model.mu, delta=model.delta, offset=model.offset, scale=model.scale,
                     regressors=regressors, targets=targets, alpha=model.alpha,
                     bias=model.bias, period=self.period,
                     train=json.dumps(self.train, sort_keys=True),
                     arx_centres=self.arx_centres, arx_width=self.arx_width,
                     arx_coefficients=self.arx_coefficients)
        os.replace(partial, path)


def file_digest(path) -> str:
    with open(path, "rb") as handle:
        return hashlib.sha256(handle.read()).hexdigest()


# What a model file may hold. The file and what its members expand to are bounded before
# anything is decompressed (a deflated member of zeros expands a thousandfold), and the
# dictionary (identification samples + the correction window) before the kernel matrix and
# its factor, (samples + window)^2 floats each, are allocated: 8192 is 0.5 GiB apiece,
# several times the shipped model's 900 + 500.
MAX_FILE_BYTES = 64 << 20
MAX_EXPANDED_BYTES = 64 << 20
MAX_DICTIONARY = 8192
# The members FORMAT names, with their dtype kind (f: float64, i: integer, U: text) and
# number of dimensions; nothing else in the archive is read.
MEMBERS = {"format": ("U", 0), "layout": ("i", 1), "mu": ("f", 0), "delta": ("f", 0),
           "offset": ("f", 1), "scale": ("f", 1), "regressors": ("f", 2), "targets": ("f", 1),
           "alpha": ("f", 1), "bias": ("f", 0), "period": ("f", 0), "train": ("U", 0),
           "arx_centres": ("f", 1), "arx_width": ("f", 0), "arx_coefficients": ("f", 2)}
KINDS = {"f": "float64", "i": "integer", "U": "text"}


def _read_members(path, data: bytes) -> dict[str, np.ndarray]:
    """The members MEMBERS names, each checked for its dtype, its dimensions and (floats)
    finiteness, their sizes bounded from the zip directory and each array's header
    before any data is read."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        infos = {}
        for name in MEMBERS:
            try:
                infos[name] = archive.getinfo(f"{name}.npy")
            except KeyError:
                raise ScenarioError(f"model file {path} lacks the field {name}") from None
        expanded = sum(info.file_size for info in infos.values())
        if expanded > MAX_EXPANDED_BYTES:
            raise ScenarioError(f"model file {path}: its arrays expand to {expanded / 2**20:.0f}"
                                f" MiB, more than {MAX_EXPANDED_BYTES >> 20} MiB")
        fields = {}
        for name, (kind, dimensions) in MEMBERS.items():
            with archive.open(infos[name]) as member:
                version = np.lib.format.read_magic(member)
                shape, _, dtype = (np.lib.format.read_array_header_1_0(member)
                                   if version == (1, 0)
                                   else np.lib.format.read_array_header_2_0(member))
            if dtype.kind != kind or (kind == "f" and dtype != np.float64) \
                    or len(shape) != dimensions:
                raise ScenarioError(f"model file {path}: {name} is a {len(shape)}-dimensional "
                                    f"{dtype} array, not a {dimensions}-dimensional "
                                    f"{KINDS[kind]} one")
            if math.prod(shape) * dtype.itemsize > infos[name].file_size:
                raise ScenarioError(f"model file {path}: {name} claims more data than it holds")
            with archive.open(infos[name]) as member:
                fields[name] = np.lib.format.read_array(member, allow_pickle=False)
            if kind == "f" and not np.all(np.isfinite(fields[name])):
                raise ScenarioError(f"model file {path}: {name} holds non-finite numbers")
    except ScenarioError:
        raise
    except (OSError, ValueError, EOFError, RuntimeError, NotImplementedError,
            zipfile.BadZipFile) as exc:  # RuntimeError: an encrypted member
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ScenarioError(f"model file {path} is not a readable .npz archive ({reason})"
                            ) from None
    return fields


def load_model(path, window: int = 0) -> ModelFile:
    """Read and check a model file: one-line ScenarioError for a missing, corrupt,
    truncated, oversized or inconsistent one (see MEMBERS, MAX_*). The file is read
    every time; the same bytes with the same window are solved once per process (a
    run builds its controller twice, in prepare() and in simulate(); a tuner's runs
    build it again and again) and each caller gets its own copy of the model."""
    loaded = _solved_model(path, yamlfile.read_bytes(path, "model file", MAX_FILE_BYTES),
                           window)
    return replace(loaded, lssvm=copy.deepcopy(loaded.lssvm))


@functools.lru_cache(maxsize=2)  # a model of 900 samples + a window of 500: 17 MB
def _solved_model(path, data: bytes, window: int) -> ModelFile:
    """The model file's contents, checked and solved; never changed by a caller (the
    LSSVM is copied, the multi-model's arrays are read-only)."""
    fields = _read_members(path, data)
    if str(fields["format"]) != FORMAT:
        raise ScenarioError(f"model file {path}: format {str(fields['format'])!r}, "
                            f"expected {FORMAT!r}")
    if fields["layout"].shape != (3,):
        raise ScenarioError(f"model file {path}: layout must be [na, nb, nk]")
    try:
        layout = Layout(*(int(v) for v in fields["layout"]))
    except ValueError as exc:
        raise ScenarioError(f"model file {path}: {exc}") from None
    regressors, targets = fields["regressors"], fields["targets"]
    centres, coefficients = fields["arx_centres"], fields["arx_coefficients"]
    if (regressors.shape[1] != layout.size or targets.shape != (len(regressors),)
            or len(targets) < 2 or fields["alpha"].shape != targets.shape
            or fields["offset"].shape != (layout.size,)
            or fields["scale"].shape != (layout.size,)):
        raise ScenarioError(f"model file {path}: arrays of inconsistent shapes")
    if not np.all(fields["scale"] > 0):
        raise ScenarioError(f"model file {path}: a zero or negative scale")
    if len(targets) + window > MAX_DICTIONARY:
        raise ScenarioError(f"model file {path}: its {len(targets)} samples and gpc.window "
                            f"{window} exceed the {MAX_DICTIONARY} samples a model may hold")
    if len(centres) < 1 or coefficients.shape != (len(centres), 1 + layout.size):
        raise ScenarioError(f"model file {path}: the multi-model's arrays do not match its "
                            f"layout")
    if not (fields["arx_width"] > 0 and fields["period"] > 0):
        raise ScenarioError(f"model file {path}: arx_width and period must be positive")
    try:
        model = LSSVM(layout, float(fields["mu"]), float(fields["delta"]), fields["offset"],
                      fields["scale"], regressors, targets, window)
        train = json.loads(str(fields["train"]))
    except ValueError as exc:
        raise ScenarioError(f"model file {path}: {exc}") from None
    if not isinstance(train, dict):
        raise ScenarioError(f"model file {path}: train must be a JSON object")
    if not np.allclose(model.alpha, fields["alpha"], rtol=1e-6,
                       atol=1e-9 * max(1.0, float(np.abs(fields["alpha"]).max()))):
        raise ScenarioError(f"model file {path}: its coefficients do not solve its samples "
                            f"(a changed or corrupt file)")
    centres.flags.writeable = coefficients.flags.writeable = False
    return ModelFile(model, float(fields["period"]), train, centres,
                     float(fields["arx_width"]), coefficients)
