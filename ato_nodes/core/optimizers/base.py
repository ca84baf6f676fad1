"""What every optimizer of this package shares: budget, bounds, seed, stops, history.

An algorithm is a subclass of `Optimizer` that implements `_start(run)` (build
and evaluate the initial population, returning the algorithm's state) and
`_step(run, state)` (one iteration). `Optimizer.minimize` drives the loop; the
`Run` it hands to the algorithm is the algorithm's only way to the fitness:

* Fitness: `f(X) -> values`, X of shape (n, d), values of shape (n,), lower is
  better. `Run.evaluate` passes a whole batch in one call (the caller may
  evaluate it in parallel) and hands the fitness a copy, so the fitness cannot
  alter the algorithm's state.
* Budget, in fitness evaluations: every row of every batch counts, probes
  (antennae, food centres, opposite points) included. A batch that would
  overrun the budget is truncated: only its first rows are evaluated and the
  others get +inf, so the algorithm can finish its iteration without special
  cases, and the loop then stops with reason "budget". The fitness is never
  called with an empty batch.
* Non-finite fitness values (NaN, +-inf: e.g. a diverged simulation) become
  +inf, the worst value: they never beat a finite value, and comparisons stay
  well defined. Algorithms that do arithmetic on fitness values (entropy, krill
  herd's normalised differences) use `finite_or_worst`. Finite values are
  clipped to +-1e300, so sums and differences of them cannot overflow.
* Bounds: every evaluated candidate lies in [lower, upper]; `Run.evaluate`
  rejects one that does not (or is NaN), as an optimizer bug. Each algorithm
  documents how it brings its moves back into the box (mostly by clipping).
* Best so far: over every evaluated candidate, whatever its role in the
  algorithm (an antenna probe that happens to be better than every particle is
  a point the caller paid for, so it is reported). Particle-swarm algorithms use
  it as gbest.
* Seed: an int (turned into `numpy.random.default_rng(seed)`) or a
  `numpy.random.Generator`; all randomness comes from it. Schedules depend on
  the iteration index and on `Run.planned_iterations`, which follows from the
  budget alone, never on the clock. Hence deterministic replay: the same seed
  and the same fitness values give the same sequence of batches (pass an int
  for that: a Generator's state moves on with each run).
* Iterations: the initialisation is iteration 0, and each `_step` is one more;
  the history has one record per iteration and `Result.iterations` is their
  number. A record holds the best fitness and position so far, the
  evaluations used so far and the mean of the finite values evaluated during
  that iteration (+inf if there were none).
* Stops, checked between iterations: budget exhausted ("budget"); optional wall
  time in seconds ("wall_time"; the initialisation always completes); optional
  stall ("stall"): the best value has not dropped by more than
  `stall_tolerance` (absolute) for `stall_iterations` iterations in a row.
* Bounds for pruning (`minimize(..., bounded=True)`): an algorithm that can say,
  per candidate, a value at or above which the candidate's exact fitness changes
  nothing it will do passes it with the batch, and the fitness is then called as
  f(X, bounds): it may stop a candidate as soon as its value provably reaches its
  bound and return any value >= the bound (a lower bound of the true one). The
  PSO and BAS-PSO moves bound each particle by its own best (a worse value only
  sets the particle's current value, which they never use); GA-PSO, APSO and
  AW-PSO use every current value, BAS's antennae need both exact values, WSO and
  KH rank all: they pass none. Best-so-far and history are unchanged by it; the
  iteration means then average lower bounds.
* Start point x0 (e.g. a paper's gains): clipped into the box and placed as
  row 0 of the initial population, the rest being sampled as the algorithm
  does without it; single-agent algorithms start from it.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np

Fitness = Callable[[np.ndarray], np.ndarray]
Seed = int | np.random.Generator


class StopReason(str, Enum):
    BUDGET = "budget"
    WALL_TIME = "wall_time"
    STALL = "stall"


@dataclass(frozen=True)
class IterationRecord:
    iteration: int
    evaluations: int
    best_f: float
    mean_f: float
    best_x: np.ndarray


@dataclass
class Result:
    algorithm: str
    best_x: np.ndarray
    best_f: float
    evaluations: int
    iterations: int
    stop_reason: StopReason
    history: list[IterationRecord]

    def trace(self, field: str) -> np.ndarray:
        """One field of the history as an array, e.g. trace("best_f") for a
        convergence curve or trace("best_x") of shape (iterations, d)."""
        return np.array([getattr(record, field) for record in self.history])


LARGEST_VALUE = 1e300  # finite values are clipped to +-this: their differences cannot overflow


def finite_or_worst(values: np.ndarray) -> np.ndarray:
    """Fitness values fit for arithmetic: +inf replaced by the worst finite value
    (all zeros if none is finite), so non-finite candidates rank as tied worst."""
    finite = np.isfinite(values)
    if not finite.any():
        return np.zeros_like(values)
    return np.where(finite, values, values[finite].max())


class Run:
    """One optimisation run as an algorithm sees it: the box, the random
    generator, the evaluation budget and the best point so far."""

    def __init__(self, fitness: Fitness, lower: np.ndarray, upper: np.ndarray, budget: int,
                 rng: np.random.Generator, x0: np.ndarray | None, planned_iterations: int,
                 bounded: bool = False):
        self.lower, self.upper = lower, upper
        self.span = upper - lower
        self.dim = len(lower)
        self.rng = rng
        self.budget = budget
        self.x0 = x0
        self.planned_iterations = planned_iterations
        self.iteration = 0
        self.evaluations = 0
        self.best_x: np.ndarray | None = None
        self.best_f = np.inf
        self._fitness = fitness
        self.bounded = bounded
        self._iteration_sum = 0.0
        self._iteration_count = 0

    @property
    def remaining(self) -> int:
        return self.budget - self.evaluations

    @property
    def progress(self) -> float:
        """iteration / planned iterations, in [0, 1] (a last, truncated
        iteration beyond the plan stays at 1)."""
        return min(self.iteration / self.planned_iterations, 1.0)

    def clip(self, x: np.ndarray) -> np.ndarray:
        return np.clip(x, self.lower, self.upper)

    def uniform(self, n: int) -> np.ndarray:
        # clip: lower + r * span can round to one ulp past upper
        return self.clip(self.lower + self.rng.random((n, self.dim)) * self.span)

    def with_start_point(self, population: np.ndarray) -> np.ndarray:
        """The population with x0, if given, as its row 0."""
        if self.x0 is not None:
            population[0] = self.x0
        return population

    def initial_population(self, n: int) -> np.ndarray:
        """n points uniform in the box, x0 (if given) first."""
        return self.with_start_point(self.uniform(n))

    def evaluate(self, candidates: np.ndarray, bounds: np.ndarray | None = None) -> np.ndarray:
        """Fitness of a batch, in one call; see the module docstring for the
        budget truncation, the treatment of non-finite values and `bounds`."""
        candidates = np.asarray(candidates, dtype=float)
        if candidates.ndim != 2 or candidates.shape[1] != self.dim:
            raise ValueError(f"a batch must have shape (n, {self.dim}), got {candidates.shape}")
        if not (np.all(candidates >= self.lower) and np.all(candidates <= self.upper)):
            raise ValueError("optimizer bug: a candidate is NaN or outside the bounds")
        values = np.full(len(candidates), np.inf)
        count = min(len(candidates), self.remaining)
        if count == 0:
            return values
        if self.bounded and bounds is not None:
            raw = self._fitness(candidates[:count].copy(), np.array(bounds[:count], dtype=float))
        else:
            raw = self._fitness(candidates[:count].copy())
        raw = np.asarray(raw, dtype=float)
        if raw.shape != (count,):
            raise ValueError(f"the fitness must return shape ({count},), got {raw.shape}")
        values[:count] = np.where(np.isfinite(raw), np.clip(raw, -LARGEST_VALUE, LARGEST_VALUE),
                                  np.inf)
        self.evaluations += count
        best = int(np.argmin(values[:count]))
        if self.best_x is None or values[best] < self.best_f:
            self.best_x, self.best_f = candidates[best].copy(), float(values[best])
        finite = values[:count][np.isfinite(values[:count])]
        self._iteration_sum += float(finite.sum())
        self._iteration_count += len(finite)
        return values

    def close_iteration(self) -> IterationRecord:
        """The record of the iteration just finished; starts the next one."""
        mean = self._iteration_sum / self._iteration_count if self._iteration_count else np.inf
        self._iteration_sum, self._iteration_count = 0.0, 0
        return IterationRecord(self.iteration, self.evaluations, self.best_f, mean,
                               self.best_x.copy())


class _StallWatch:
    def __init__(self, iterations: int | None, tolerance: float, best_f: float):
        self.iterations, self.tolerance = iterations, tolerance
        self.reference, self.count = best_f, 0

    def update(self, best_f: float) -> None:
        if best_f < self.reference - self.tolerance:
            self.reference, self.count = best_f, 0
        else:
            self.count += 1

    @property
    def stalled(self) -> bool:
        return self.iterations is not None and self.count >= self.iterations


def _stop_reason(run: Run, started: float, max_time: float | None,
                 stall: _StallWatch) -> StopReason | None:
    if run.remaining == 0:
        return StopReason.BUDGET
    if max_time is not None and time.monotonic() - started >= max_time:
        return StopReason.WALL_TIME
    if stall.stalled:
        return StopReason.STALL
    return None


def _as_generator(seed: Seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
        return np.random.default_rng(int(seed))
    raise TypeError("seed must be an int or a numpy.random.Generator")


def _box(lower: Any, upper: Any, x0: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    lower = np.atleast_1d(np.asarray(lower, dtype=float))
    upper = np.atleast_1d(np.asarray(upper, dtype=float))
    if lower.ndim != 1 or lower.shape != upper.shape:
        raise ValueError("lower and upper must be 1-D arrays of the same length")
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)) and np.all(lower < upper)):
        raise ValueError("bounds must be finite with lower < upper in every dimension")
    if x0 is None:
        return lower, upper, None
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != lower.shape or not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 must be a finite array of shape {lower.shape}")
    return lower, upper, np.clip(x0, lower, upper)


class Optimizer(ABC):
    """Base of every algorithm; subclasses set `name` and implement the hooks."""

    name: str

    @abstractmethod
    def initial_evaluations(self) -> int:
        """Evaluations spent by `_start` (used to plan the iteration count)."""

    @abstractmethod
    def evaluations_per_iteration(self) -> int:
        """Evaluations spent by one `_step`."""

    @abstractmethod
    def _start(self, run: Run) -> Any:
        """Build and evaluate the initial population; return the state."""

    @abstractmethod
    def _step(self, run: Run, state: Any) -> None:
        """One iteration, updating `state` in place."""

    def minimize(self, fitness: Fitness, lower: Any, upper: Any, budget: int, seed: Seed, *,
                 x0: Any = None, max_time: float | None = None,
                 stall_iterations: int | None = None, stall_tolerance: float = 0.0,
                 bounded: bool = False) -> Result:
        """Minimise `fitness` over [lower, upper]; see the module docstring (with
        `bounded`, the fitness takes (X, bounds))."""
        lower, upper, x0 = _box(lower, upper, x0)
        if int(budget) != budget or budget < 1:
            raise ValueError("budget must be a positive whole number of evaluations")
        if stall_iterations is not None and stall_iterations < 1:
            raise ValueError("stall_iterations must be at least 1")
        budget = int(budget)
        planned = max(1, (budget - self.initial_evaluations()) // self.evaluations_per_iteration())
        run = Run(fitness, lower, upper, budget, _as_generator(seed), x0, planned, bounded)
        started = time.monotonic()
        state = self._start(run)
        history = [run.close_iteration()]
        stall = _StallWatch(stall_iterations, stall_tolerance, run.best_f)
        while (reason := _stop_reason(run, started, max_time, stall)) is None:
            run.iteration += 1
            self._step(run, state)
            history.append(run.close_iteration())
            stall.update(run.best_f)
        return Result(self.name, run.best_x.copy(), run.best_f, run.evaluations, len(history),
                      reason, history)
