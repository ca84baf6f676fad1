"""The optimizer library's contract: reproducible, budget-exact, bounded, robust."""

from __future__ import annotations

import time

import numpy as np
import pytest

from ato_nodes.core.optimizers import ALGORITHMS, StopReason, optimize
from ato_nodes.core.optimizers.apso import entropy_bin_edges, fitness_entropy, rate_limited_ramp

NAMES = list(ALGORITHMS)
DIM = 5
LOWER, UPPER = -np.full(DIM, 100.0), np.full(DIM, 100.0)


def sphere(x: np.ndarray) -> np.ndarray:
    return np.sum(x * x, axis=1)


class Recorder:
    """Wraps a batch fitness: records every batch, checks it is a finite batch
    inside the bounds."""

    def __init__(self, function, lower=LOWER, upper=UPPER):
        self.function, self.lower, self.upper = function, lower, upper
        self.batches: list[np.ndarray] = []

    def __call__(self, x: np.ndarray) -> np.ndarray:
        assert x.ndim == 2 and x.shape[1] == len(self.lower) and len(x) > 0
        assert np.all(np.isfinite(x))
        assert np.all(x >= self.lower) and np.all(x <= self.upper)
        self.batches.append(x.copy())
        return self.function(x)

    @property
    def evaluations(self) -> int:
        return sum(len(batch) for batch in self.batches)


def traces(result) -> list[np.ndarray]:
    return [result.trace(field) for field in ("best_f", "mean_f", "evaluations", "best_x")]


@pytest.mark.parametrize("name", NAMES)
def test_same_seed_same_run_other_seed_other_run(name):
    runs = []
    for seed in (11, 11, 12):
        recorder = Recorder(sphere)
        runs.append((optimize(name, recorder, LOWER, UPPER, 500, seed), recorder.batches))
    (first, batches), (again, batches_again), (other, _) = runs
    assert all(np.array_equal(a, b) for a, b in zip(traces(first), traces(again), strict=True))
    assert len(batches) == len(batches_again)
    assert all(np.array_equal(a, b) for a, b in zip(batches, batches_again, strict=True))
    assert not np.array_equal(first.trace("best_x"), other.trace("best_x"))


@pytest.mark.parametrize("name", NAMES)
def test_generator_seed_is_accepted(name):
    from_int = optimize(name, sphere, LOWER, UPPER, 200, 5)
    from_generator = optimize(name, sphere, LOWER, UPPER, 200, np.random.default_rng(5))
    assert np.array_equal(from_int.trace("best_f"), from_generator.trace("best_f"))


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("budget", [1, 3, 257, 1000])
def test_budget_is_exact(name, budget):
    recorder = Recorder(sphere)
    result = optimize(name, recorder, LOWER, UPPER, budget, 0)
    assert recorder.evaluations == result.evaluations == budget
    assert result.stop_reason == StopReason.BUDGET
    assert result.history[-1].evaluations == budget
    assert len(result.history) == result.iterations
    assert np.all(np.diff(result.trace("evaluations")) > 0)


@pytest.mark.parametrize("name", NAMES)
def test_improves_far_below_the_initial_population(name):
    result = optimize(name, sphere, LOWER, UPPER, 2000, 3)
    initial_best = result.history[0].best_f
    assert result.best_f < 0.05 * initial_best
    assert np.all(np.diff(result.trace("best_f")) <= 0)
    assert result.best_f == pytest.approx(sphere(result.best_x[None])[0])


@pytest.mark.parametrize("name", NAMES)
def test_non_finite_values_never_win(name):
    def half_broken(x):
        values = sphere(x)
        values[x[:, 0] > 0] = np.nan  # a "diverged simulation" on half the box
        values[x[:, 1] > 50] = np.inf
        values[x[:, 1] < -50] = -np.inf
        return values

    recorder = Recorder(half_broken)
    result = optimize(name, recorder, LOWER, UPPER, 600, 2)
    assert np.isfinite(result.best_f)
    assert result.best_x[0] <= 0 and -50 <= result.best_x[1] <= 50
    assert np.all(np.isfinite(result.trace("best_f")))


@pytest.mark.parametrize("name", NAMES)
def test_all_nan_fitness_does_not_crash(name):
    recorder = Recorder(lambda x: np.full(len(x), np.nan))
    result = optimize(name, recorder, LOWER, UPPER, 300, 4)
    assert result.evaluations == 300 and result.best_f == np.inf
    assert np.all(result.trace("mean_f") == np.inf)


@pytest.mark.parametrize("name", NAMES)
def test_candidates_stay_in_asymmetric_bounds(name):
    lower, upper = np.array([-1.0, 0.0, 10.0, -5.0, 2.0]), np.array([1.0, 0.5, 1000.0, -4.0, 3.0])
    # optimum outside the box: the search presses against the walls
    recorder = Recorder(lambda x: np.sum((x - 2.0 * upper) ** 2, axis=1), lower, upper)
    result = optimize(name, recorder, lower, upper, 800, 6, x0=upper + 5.0)
    assert np.all(result.best_x >= lower) and np.all(result.best_x <= upper)
    assert recorder.evaluations == 800


@pytest.mark.parametrize("name", [n for n in NAMES if n != "bas"])
def test_x0_is_in_the_initial_population(name):
    x0 = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    recorder = Recorder(sphere)
    optimize(name, recorder, LOWER, UPPER, 300, 8, x0=x0)
    assert any(np.array_equal(row, x0) for row in recorder.batches[0])


def test_bas_senses_around_x0():
    x0 = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    recorder = Recorder(sphere)
    optimize("bas", recorder, LOWER, UPPER, 10, 8, x0=x0)
    left, right = recorder.batches[0]
    np.testing.assert_allclose((left + right) / 2, x0)


@pytest.mark.parametrize("name", NAMES)
def test_wall_time_stop(name):
    def slow(x):
        time.sleep(0.002)
        return sphere(x)

    result = optimize(name, slow, LOWER, UPPER, 10**7, 1, max_time=0.02)
    assert result.stop_reason == StopReason.WALL_TIME
    assert result.evaluations < 10**7


@pytest.mark.parametrize("name", NAMES)
def test_stall_stop_on_constant_fitness(name):
    result = optimize(name, lambda x: np.ones(len(x)), LOWER, UPPER, 10**6, 1,
                      stall_iterations=4)
    assert result.stop_reason == StopReason.STALL
    assert result.iterations == 1 + 4  # the initialisation, then 4 without improvement


def test_stall_tolerance_ignores_tiny_improvements():
    calls = iter(range(10**6))

    def creeping(x):
        return np.array([1.0 - 1e-9 * next(calls) for _ in x])

    result = optimize("pso", creeping, LOWER, UPPER, 10**6, 1, stall_iterations=3,
                      stall_tolerance=1e-3)
    assert result.stop_reason == StopReason.STALL and result.iterations == 4


def test_unknown_algorithm_and_bad_arguments():
    with pytest.raises(ValueError, match="known:"):
        optimize("nelder-mead", sphere, LOWER, UPPER, 100, 0)
    with pytest.raises(ValueError):
        optimize("pso", sphere, UPPER, LOWER, 100, 0)
    with pytest.raises(ValueError):
        optimize("pso", sphere, LOWER, UPPER, 0, 0)
    with pytest.raises(ValueError, match="shape"):
        optimize("pso", lambda x: np.zeros(len(x) + 1), LOWER, UPPER, 100, 0)


def test_apso_learning_factors_move_at_most_delta_per_iteration():
    values = [rate_limited_ramp(2.0, 0.5, g, 10, 0.05) for g in range(40)]
    assert values[0] == 2.0 and values[-1] == pytest.approx(0.5)
    assert np.max(np.abs(np.diff(values))) <= 0.05 + 1e-12


def test_apso_entropy_is_one_at_the_start_and_zero_when_converged():
    initial = np.random.default_rng(0).random(50) * 100.0
    edges = entropy_bin_edges(initial, 10)
    assert fitness_entropy(initial, edges) == pytest.approx(1.0)
    assert fitness_entropy(np.full(50, initial.min()), edges) == 0.0
    assert fitness_entropy(np.full(50, np.nan), edges) == 0.0


def rastrigin(x: np.ndarray) -> np.ndarray:
    return 10 * x.shape[1] + np.sum(x * x - 10 * np.cos(2 * np.pi * x), axis=1)


@pytest.mark.parametrize("name", NAMES)
def test_pruned_values_above_the_bounds_change_no_result(name):
    """A fitness that answers any value at or above its bound with a lower bound only
    (what a pruned candidate returns) leaves best, best point and best-so-far history
    as they are; the PSO and BAS-PSO moves do bound their candidates."""
    lower, upper = np.full(4, -5.0), np.full(4, 5.0)
    bounded_calls = []

    def pruned(x, bounds=None):
        values = rastrigin(x)
        if bounds is None:
            return values
        bounded_calls.append(np.isfinite(bounds).sum())
        return np.where(values >= bounds, np.minimum(values, bounds + 1e-3), values)

    exact = optimize(name, rastrigin, lower, upper, budget=300, seed=5)
    cut = optimize(name, pruned, lower, upper, budget=300, seed=5, bounded=True)
    assert cut.best_f == exact.best_f and np.array_equal(cut.best_x, exact.best_x)
    assert np.array_equal(cut.trace("best_f"), exact.trace("best_f"))
    assert (sum(bounded_calls) > 0) == (name in ("pso", "bas-pso"))
