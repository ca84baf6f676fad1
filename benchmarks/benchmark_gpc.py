#!/usr/bin/env python3
"""Benchmark seed 001's GPC: controller cost per step, QP solvers, stack rate.

    python benchmarks/benchmark_gpc.py [--duration 600] [--no-stack]

1. Controller cost per step (median, p99, max), the kind's step (ControllerSteps.step,
   what the controller node's SteppedController calls) timed around every call of a
   whole in-process run of the Python loop: the code the node runs per step, without
   the messages. For each GPC prediction model and, beside them,
   the ADRC and PID kinds of the comparison (their scenario files' gains).
2. The QP at this size (Nu = 3 and 5 moves, the shipped constraints): the GPC's own
   (core/control/qp.py, compiled), DAQP, and quadprog if installed (pip install
   quadprog), against the closed form; then every QP of the shipped GPC scenarios' whole
   runs solved by the GPC's solver and by DAQP: the largest difference of the solutions,
   relative to the largest move (at least 1 N/kN).
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
from ato_nodes.core.base.kernels import compiled
from ato_nodes.core.config.scenario import prepare, scenario_names
from ato_nodes.core.control import gpc_steps, lssvm, qp
from ato_nodes.core.run import fast_loop, loop
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
    """Seconds of every controller step of one in-process run of the Python loop (the
    kind's step as its node calls it)."""
    costs = []
    original = fast_loop.controller_step

    def timed(*arguments):
        started = time.perf_counter()
        result = original(*arguments)
        costs.append(time.perf_counter() - started)
        return result

    fast_loop.controller_step = timed
    try:
        loop.simulate(values, compiled=False)
    finally:
        fast_loop.controller_step = original
    return np.array(costs)


def _solve_compiled(hessian, gradient, rows, lower, upper):
    x = np.empty(len(gradient))
    flag = qp.solve_qp(hessian, gradient, rows, lower, upper, x, qp.work_space(len(x)))
    return x, flag


solve_compiled = compiled(_solve_compiled) or _solve_compiled


def shipped_qps(values) -> list[tuple]:
    """Every QP (hessian, gradient, rows, lower, upper) a run of `values` solves: the
    controller's step run as Python (its model's linearisation and corrections
    compiled) with its QP recorded, the run otherwise the loop's."""
    problems = []
    original = gpc_steps.first_move

    def recorded(settings, hessian, gradient, previous, low, high, max_change):
        if settings.constrained:
            problems.append((hessian, gradient, *gpc_steps.constraints(
                settings.moves, previous, low, high, max_change)))
        return original(settings, hessian, gradient, previous, low, high, max_change)

    patches = {"compiled_step": gpc_steps._gpc_step, "first_move": recorded,
               "_linearise_dictionary": lssvm.linearise_dictionary,
               "_add_sample": lssvm.add_sample}
    saved = {name: getattr(gpc_steps, name) for name in patches}
    try:
        for name, value in patches.items():
            setattr(gpc_steps, name, value)
        loop.simulate(values, compiled=False)
    finally:
        for name, value in saved.items():
            setattr(gpc_steps, name, value)
    return problems


def against_daqp(problems) -> tuple[float, int]:
    """(largest |x - x_daqp| over the problems, relative to max(1, |x_daqp|), problems
    either solver did not solve)."""
    import daqp
    worst, unsolved = 0.0, 0
    for hessian, gradient, rows, lower, upper in problems:
        x, flag = solve_compiled(hessian, gradient, rows, lower, upper)
        reference, _, reference_flag, _ = daqp.solve(hessian, gradient, rows, upper, lower)
        if flag != qp.SOLVED or reference_flag < 1:
            unsolved += 1
            continue
        scale = max(1.0, float(np.abs(reference).max()))
        worst = max(worst, float(np.abs(x - reference).max()) / scale)
    return worst, unsolved


def gpc_scenarios() -> list[str]:
    return [name for name in scenario_names() if prepare(name)["controller.kind"] == "gpc"]


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

    rows = np.vstack([np.eye(nu), cumulative])
    bounds = np.concatenate([-moves, lower]), np.concatenate([moves, upper])
    timings["qp.py (compiled)"] = timed(lambda g: solve_compiled(hessian, g, rows, *bounds))
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
    for name in gpc_scenarios():
        problems = shipped_qps(prepare(name))
        worst, unsolved = against_daqp(problems)
        print(f"{name}: {len(problems)} QPs, qp.py against DAQP: largest difference "
              f"{worst:.1e} relative, {unsolved} not solved by either")
    if args.no_stack:
        return
    with tempfile.TemporaryDirectory() as scratch:
        gpc = stack_rate(runs["gpc lssvm (adaptive)"], Path(scratch) / "gpc")
        adrc = stack_rate(runs["han_adrc"], Path(scratch) / "adrc")
    print(f"stack rate: gpc {gpc:.0f} steps/s, han_adrc {adrc:.0f} steps/s: gpc at "
          f"{100 * gpc / adrc:.0f} % of the ADRC's (target >= 70 %)")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
