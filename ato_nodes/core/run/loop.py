"""The lockstep loop in one process: simulate() builds the ROS nodes' three stages and
runs their steps in the one loop of core/run/fast_loop.py (core/run/stages.py gives the
order), compiled or as Python, so the nodes and both give identical numbers.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..config.components import CONTROLLERS
from ..config.scenario import apply_overrides, load_scenario, scenario_names
from ..control import lssvm
from ..config.schema import SPEC_BY_NAME, NodeValues
from ..scoring.indices import RunningIndex
from ..train.lines import line_of
from . import fast_loop
from .located import ODOMETRY_SERIES
from .stages import SERIES, ControllerStage, PlantStage, ProfileStage

def simulate(values: dict[str, Any], deadline: float | None = None,
             prune: tuple[RunningIndex, float] | None = None,
             changes: dict[int, dict[str, float]] | None = None, compiled: bool = True,
             replans: list | None = None) -> dict[str, np.ndarray]:
    """Run the loop in this process: one array per SERIES name, per controller output
    and `preview` (the horizons, steps x (N + 1)), one entry per step. Each stage
    gets exactly what its node declares. A diverged run (see PlantStage.diverged)
    ends early, as it does in the stack, and so does a journey whose train has stood
    run.last_stop_hold at its last stop (PlantStage.arrived). Past `deadline`
    (time.monotonic()) it raises TimeoutError (checked between chunks of steps, each a
    small part of a second). prune (running, limit): a tuner's pruning, `running` takes
    every step's (t, target - true speed) and the run ends once its value passes
    `limit`. changes {step: {name: value}}: live controller parameters changed before
    that step, as a run's bag records them (bagio.Run.parameter_changes). The loop of
    core/run/fast_loop.py runs compiled when numba is installed; compiled=False runs the
    same function as Python, to the same bits. replans: a list the run's mid-run re-plans
    (core/targets/replan.CurveReplan, profile.replan) are appended to, as the bag keeps
    them."""
    line = line_of(values)
    profile = ProfileStage(NodeValues("profile", values), line)
    plant = PlantStage(NodeValues("plant", values), line)
    controller = ControllerStage(NodeValues("controller", values), line)
    rows, extras, horizons, located_rows = fast_loop.run(
        profile, plant, controller, prune, lambda step: _check_deadline(deadline, step),
        changes, compiled)
    if replans is not None:
        replans.extend(profile.replans)
    series = _series(rows, extras, horizons, controller.output_names)
    if plant.odometry is not None:
        series.update({name: located_rows[:, i] for i, name in enumerate(ODOMETRY_SERIES)})
    return series


def _check_deadline(deadline: float | None, step: int) -> None:
    if deadline is not None and time.monotonic() > deadline:
        raise TimeoutError(f"the simulation passed its deadline at step {step}")


def _series(rows, extras, horizons, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    table = np.array(rows, dtype=float).reshape(-1, len(SERIES))
    series = {name: table[:, i] for i, name in enumerate(SERIES)}
    extra_table = np.array(extras, dtype=float).reshape(-1, len(names))
    series.update({name: extra_table[:, i] for i, name in enumerate(names)})
    series["preview"] = np.array(horizons, dtype=float).reshape(len(rows), -1)
    return series


def warm(values: dict | None = None) -> None:
    """Compile the loop of core/run/fast_loop.py now, or load it from its cache, by a
    two-step run of `values` (default: the shipped seed000) with each controller kind
    that has compiled steps (with the on-board estimator as `values` have it, for the
    kinds that use it: on, a signature of its own; with the kind's warm_up overrides, a
    cheap run of it), and one of seed000 with the first kind without them that names a
    cheap run (its registry entry's warm_up: those kinds share one signature), by default
    also the shipped journeys' kinds (a journey's loop reads its tables: a signature of
    its own per kind) and seed 002's strategy driven again for a weighed train; and the
    LSSVM's solves. Every other run of a kind calls the loop with the same argument
    types, so these compilations serve them all, in every process of this checkout,
    until a source a signature is built from changes (core/base/kernels.py: that
    signature alone is then compiled again)."""
    warm_journeys = values is None  # setup's: a tuning warms its own run's kind
    values = load_scenario("seed000") if values is None else values
    shortest = SPEC_BY_NAME["run.duration"].low
    duration = max(2 * values["run.period"], shortest)
    for kind in fast_loop.compiled_kinds():
        estimates = CONTROLLERS[kind].estimates  # else no estimate, nor plans made from it
        simulate(apply_overrides(values, {
            "run.duration": duration, "controller.kind": kind,
            "estimator.enabled": values["estimator.enabled"] and estimates,
            "profile.replan.enabled": values["profile.replan.enabled"] and estimates,
            **dict(CONTROLLERS[kind].warm_up)}))
    cheap = next((component for component in CONTROLLERS.components.values()
                  if not component.steps and component.warm_up), None)
    if cheap is not None:
        seed000 = load_scenario("seed000")
        simulate(apply_overrides(seed000, {
            "run.duration": 2 * seed000["run.period"], "controller.kind": cheap.kind,
            **dict(cheap.warm_up)}))
    if warm_journeys:
        _warm_journeys()
        _warm_replanned_strategy()
    lssvm.warm()


def _warm_replanned_strategy() -> None:
    """A two-step run of seed 002's strategy driven again for a heavier weighed train: the
    switching strategy's compiled runs (core/targets/strategy.py), which a study of that
    scenario's trains and its scripts call in every process."""
    strategy = load_scenario("seed002-hsr-ato")
    simulate(apply_overrides(strategy, {"run.duration": 2 * strategy["run.period"],
                                        "plant.mass_factor": 1.1}))


def _warm_journeys() -> None:
    """A two-step run of the shortest shipped journey of each controller kind (a journey's
    loop has a signature of its own per kind; building a longer journey's plan is slower)."""
    journeys = [load_scenario(name) for name in scenario_names()]
    warmed = set()
    for journey in sorted(journeys, key=lambda values: values["run.duration"]):
        if journey["profile.journey.timetable"] and journey["controller.kind"] not in warmed:
            warmed.add(journey["controller.kind"])
            simulate(apply_overrides(journey, {"run.duration": 2 * journey["run.period"]}))
