#!/usr/bin/env python3
"""Benchmark seed 001's GPC: controller cost per step, QP solvers, stack rate.

    python benchmarks/benchmark_gpc.py [--duration 600] [--no-stack]

1. Controller cost per step (median, p99, max), the controller stage's `run_ready_steps()` timed
   around every call of a whole in-process run: the code the controller node runs
   per step, without the messages. For each GPC prediction model and, beside them,
   the ADRC and PID kinds of the comparison (their scenario files' gains).
2. The QP at this size (Nu = 3 and 5 moves, the shipped constraints): DAQP, and
   quadprog if installed (pip install quadprog), against the closed form.
3. The stack's rate (steps/s of the lockstep loop) with the GPC and with the Han
   ADRC of seed001-crh380al-adrc, one run each, one after the other, in this run.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import _cli
import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.run import loop
from ato_nodes.core.run.stages import ControllerStage
from ato_nodes.studies.runner import Variant, prepare_variants

VARIANTS = {
    "gpc lssvm (adaptive)": Variant("seed001-crh380al"),
    "gpc lssvm (fixed)": Variant("seed001-crh380al", ["gpc.correction=false"]),
    "gpc multimodel": Variant("seed001-crh380al", ["gpc.prediction=multimodel"]),
    "gpc mechanistic": Variant("seed001-crh380al", ["gpc.prediction=mechanistic"]),
    "gpc lssvm unconstrained": Variant("seed001-crh380al", ["gpc.constrained=false"]),
    "han_adrc": Variant("seed001-crh380al-adrc"),
    "pid": Variant("seed001-crh380al-pid"),
}


def step_costs(values) -> np.ndarray:
    """Seconds of every ControllerStage.run_ready_steps() call of one in-process run of
    the Python loop (the controller as its node runs it)."""
    costs = []
    original = ControllerStage.run_ready_steps

    def timed(self):
        started = time.perf_counter()
        result = original(self)
        costs.append(time.perf_counter() - started)
        return result

    ControllerStage.run_ready_steps = timed
    try:
        loop.simulate(values, compiled=False)
    finally:
        ControllerStage.run_ready_steps = original
    return np.array(costs)


def qp_costs(nu: int, repeats: int = 2000) -> dict[str, float]:
    """Median microseconds per solve of a GPC-shaped QP (G from a lagged train model)."""
    import daqp
    rng = np.random.default_rng(nu)
    horizon = 20
    step = np.cumsum(np.concatenate([[0.0, 0.0], 0.0028 * (1 - 0.65 ** np.arange(1, horizon - 1))]))
    lag = np.arange(horizon)[:, None] - np.arange(nu)[None, :]
    matrix = np.where(lag >= 0, step[np.clip(lag, 0, None)], 0.0)
    hessian = matrix.T @ matrix + 1e-5 * np.eye(nu)
    cumulative = np.tril(np.ones((nu, nu)))
    problems = [matrix.T @ rng.normal(0, 0.5, horizon) for _ in range(repeats)]
    moves = np.full(nu, 12.0)
    upper, lower = np.full(nu, 40.0), np.full(nu, -50.0)
    timings = {}

    def timed(solve):
        samples = []
        for gradient in problems:
            started = time.perf_counter()
            solve(gradient)
            samples.append(time.perf_counter() - started)
        return float(np.median(samples) * 1e6), float(np.percentile(samples, 99) * 1e6)

    timings["daqp"] = timed(lambda g: daqp.solve(
        hessian, g, cumulative, np.concatenate([moves, upper]),
        np.concatenate([-moves, lower])))
    try:
        import quadprog
        constraints = np.vstack([np.eye(nu), -np.eye(nu), cumulative, -cumulative]).T
        bounds = -np.concatenate([moves, moves, upper, -lower])
        timings["quadprog"] = timed(lambda g: quadprog.solve_qp(hessian, -g, constraints,
                                                                 bounds))
    except ImportError:
        pass
    timings["closed form (unconstrained)"] = timed(lambda g: np.linalg.solve(hessian, -g))
    return timings


def stack_rate(values, bag: Path) -> float:
    from ato_nodes.launcher.launch import Stack
    outcome = Stack(values, bag, quiet=True, timeout=600).run()
    if not outcome.ok:
        _cli.fail(f"stack run failed: {outcome.message}", 1)
    return outcome.report["steps_per_second"]


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--duration", type=float, default=600.0,
                        help="simulated seconds of each run (default 600)")
    parser.add_argument("--no-stack", action="store_true", help="skip the stack runs")
    args = parser.parse_args()
    try:
        runs = prepare_variants(VARIANTS, [f"run.duration={args.duration}"])
    except ScenarioError as exc:
        _cli.fail(str(exc))
    print(f"controller cost per step, in-process, {args.duration:g} s runs "
          f"({round(args.duration / runs['pid']['run.period'])} steps):")
    for name, values in runs.items():
        costs = step_costs(values) * 1e3
        print(f"  {name:26s} median {np.median(costs):.3f} ms  p99 "
              f"{np.percentile(costs, 99):.3f} ms  max {costs.max():.2f} ms")
    for nu in (3, 5):
        print(f"QP with Nu = {nu} (median / p99 microseconds per solve): " + ", ".join(
            f"{name} {median:.1f} / {p99:.1f}" for name, (median, p99) in qp_costs(nu).items()))
    if args.no_stack:
        return
    with tempfile.TemporaryDirectory() as scratch:
        gpc = stack_rate(runs["gpc lssvm (adaptive)"], Path(scratch) / "gpc")
        adrc = stack_rate(runs["han_adrc"], Path(scratch) / "adrc")
    print(f"stack rate: gpc {gpc:.0f} steps/s, han_adrc {adrc:.0f} steps/s: gpc at "
          f"{100 * gpc / adrc:.0f} % of the ADRC's (target >= 70 %)")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
