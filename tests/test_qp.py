"""The GPC's QP solver (core/control/qp.py) against DAQP, the reference it replaced."""

import importlib
import signal
import sys
from pathlib import Path

import daqp
import numpy as np
import pytest

from ato_nodes.core.base.kernels import AVAILABLE
from ato_nodes.core.config.scenario import apply_overrides, prepare
from ato_nodes.core.config.schema import steps
from ato_nodes.core.control import qp

if AVAILABLE:
    import numba

    solve = numba.njit(lambda *arguments: qp.solve_qp(*arguments))
    space = numba.njit(qp.work_space)
else:
    solve, space = qp.solve_qp, qp.work_space


def daqp_solution(hessian, gradient, rows, lower, upper):
    x, _, flag, _ = daqp.solve(hessian, gradient, rows, upper, lower)  # as the GPC called it
    return x, flag


def gpc_like(rng, moves):
    """A QP of the GPC's shape: |du| <= a jerk limit and the command u0 + cumsum(du)
    inside bounds, the Hessian G^T G + r I."""
    forced = np.tril(rng.uniform(0.0, 0.05, (16, moves)))
    hessian = forced.T @ forced + 10.0 ** rng.uniform(-5, -2) * np.eye(moves)
    gradient = forced.T @ rng.normal(0.0, rng.choice([0.01, 1.0, 30.0]), 16)
    rows = np.vstack((np.eye(moves), np.tril(np.ones((moves, moves)))))
    rate = rng.uniform(0.1, 20.0)
    previous, low, high = rng.uniform(-60, 60), rng.uniform(-60, -1), rng.uniform(1, 60)
    reach = rate * np.arange(1, moves + 1)
    upper = np.concatenate((np.full(moves, rate), np.maximum(high, previous - reach) - previous))
    lower = np.concatenate((np.full(moves, -rate), np.minimum(low, previous + reach) - previous))
    return hessian, gradient, rows, lower, upper


@pytest.mark.parametrize("moves", [1, 2, 3, 5, 8])
def test_the_solution_is_daqps_to_1e_9(moves):
    rng = np.random.default_rng(moves)
    active = 0
    for _ in range(300):
        problem = gpc_like(rng, moves)
        x = np.empty(moves)
        assert solve(*problem, x, space(moves)) == qp.SOLVED
        reference, flag = daqp_solution(*problem)
        assert flag >= 1
        scale = max(1.0, np.abs(reference).max())
        assert np.abs(x - reference).max() <= 1e-9 * scale
        hessian, gradient, rows, lower, upper = problem
        values = rows @ x
        assert np.all(values >= lower - 1e-9) and np.all(values <= upper + 1e-9)
        active += np.any(np.isclose(values, lower) | np.isclose(values, upper))
    assert active > 100  # the constraints bind in many of them


def test_inconsistent_constraints_and_a_hessian_not_positive_definite_are_said():
    rows = np.array([[1.0, 0.0], [1.0, 0.0]])
    x = np.empty(2)
    assert solve(np.eye(2), np.zeros(2), rows, np.array([1.0, -5.0]), np.array([5.0, 0.0]),
                 x, space(2)) == qp.INFEASIBLE
    assert solve(-np.eye(2), np.zeros(2), rows, np.zeros(2), np.ones(2), x,
                 space(2)) == qp.NOT_CONVEX


def test_an_unconstrained_optimum_inside_the_bounds_is_the_closed_form():
    hessian = np.array([[2.0, 0.5], [0.5, 1.0]])
    gradient = np.array([-1.0, 0.3])
    x = np.empty(2)
    assert solve(hessian, gradient, np.eye(2), np.full(2, -10.0), np.full(2, 10.0), x,
                 space(2)) == qp.SOLVED
    np.testing.assert_allclose(x, np.linalg.solve(hessian, -gradient), rtol=1e-14)


def test_a_constraint_held_twice_over_is_solved():
    """The first move's jerk bound and the command's bound are one row, both binding:
    the second is in the first's span (a pure dual step, no singular system)."""
    rng = np.random.default_rng(11)
    for _ in range(50):
        hessian, gradient, rows, lower, upper = gpc_like(rng, 3)
        upper[3], lower[3] = upper[0], lower[0]  # u0 + du0 bounded exactly as du0 is
        gradient = -50.0 * np.abs(gradient) * rng.choice([-1.0, 1.0])  # pushes onto them
        x = np.empty(3)
        assert solve(hessian, gradient, rows, lower, upper, x, space(3)) == qp.SOLVED
        reference, flag = daqp_solution(hessian, gradient, rows, lower, upper)
        assert flag >= 1
        assert np.abs(x - reference).max() <= 1e-9 * max(1.0, np.abs(reference).max())


@pytest.fixture
def benchmark_gpc():
    """benchmarks/benchmark_gpc.py as a module; the signal handlers its scripts' prelude
    installs are pytest's again after the import."""
    handlers = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGPIPE)}
    folder = str(Path(__file__).resolve().parents[1] / "benchmarks")
    sys.path.insert(0, folder)
    try:
        module = importlib.import_module("benchmark_gpc")
    finally:
        sys.path.remove(folder)
        for number, handler in handlers.items():
            signal.signal(number, handler)
    return module


def test_every_qp_of_the_shipped_gpc_scenarios_is_daqps_to_1e_9(benchmark_gpc):
    """The first 120 s of each scenario whose controller is the GPC (the benchmark
    measures their whole runs the same way)."""
    names = benchmark_gpc.gpc_scenarios()
    assert {"seed001-crh380al", "seed001-crh380al-ato"} <= set(names)
    for name in names:
        values = apply_overrides(prepare(name), ["run.duration=120"])
        problems = benchmark_gpc.shipped_qps(values)
        assert len(problems) == steps(values)
        worst, unsolved = benchmark_gpc.against_daqp(problems)
        assert unsolved == 0 and worst <= 1e-9, name
