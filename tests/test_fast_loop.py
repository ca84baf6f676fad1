"""The loop of core/run/fast_loop.py compiled against the same function run as Python
(numba's own faithfulness: the loop is one text), and against itself run in chunks of
steps. tests/test_stages.py drives the nodes' stages against it."""

import dataclasses
import itertools
import re
from types import SimpleNamespace

import numpy as np
import pytest

from ato_nodes.core.run import fast_loop, loop, python_steps
from ato_nodes.core.base import kernels
from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.control.stepped import SteppedController
from ato_nodes.core.scoring.indices import RunningIndex
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.schema import steps
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, scenario_names
from test_berth import CREEPING

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")

VARIANTS = [
    ("seed000", []),
    ("seed000-step", []),
    ("seed000-realistic", []),  # lag, envelope, the noisy and quantised sensor
    ("seed000", ["controller.preview=3", "plant.substeps=3", "controller.max_rate=40",
                 "controller.mode_band=0.5", "controller.u_min=-60", "controller.u_max=60"]),
    ("seed000", ["plant.actuator_lag=0.6", "plant.envelope=true", "plant.mass=600",
                 "plant.hold_at_standstill=true", "adrc.implicit_nlsef=false", "adrc.mu1=50",
                 "adrc.mu2=20"]),
    ("seed000", ["controller.kind=nladrc", "controller.holding_brake=5",
                 "plant.initial_speed=10"]),
    # the on-board estimator in the linear ADRC's and the PID's state
    ("seed004-metro-ato", ["estimator.enabled=true", "plant.mass_factor=1.3",
                           "plant.resistance_factor=1.2"]),
    ("seed001-crh380al-pid", ["estimator.enabled=true", "plant.resistance_factor=0.8"]),
    # a journey's dwell and departure with the standstill-aware observer
    ("seed004-metro-line", ["ladrc.standstill=true"]),
    # two stops of a heavy train with a fast actuator, tracking where it will be
    ("seed004-metro-line", ["ladrc.prediction=position", "plant.lag_factor=0.75",
                            "plant.mass_factor=1.21"]),
    # a train stopped short standing in its berth (tests/test_berth.py)
    ("seed004-metro-ato", [*CREEPING, "profile.berth=0.1"]),
    # a strategy's stages led into past a neutral section by a resisted, heavy train
    ("seed002-hsr-ato", ["ladrc.plan_lead=15", "plant.mass_factor=1.2",
                         "plant.resistance_factor=1.2"]),
    # the ATO on its own position: the sensors' draws and the localisation (its radar
    # reads NaN under 0.3 m/s) carried from chunk to chunk
    ("seed004-metro-ato", ["odometry.enabled=true", "odometry.radar=true",
                           "odometry.accelerometer=true", "odometry.balise_spacing=500",
                           "odometry.beacon_distances=150,50,20,5"]),
]


def python_run(monkeypatch, values, prune=None):
    return simulate(values, prune=prune, compiled=False)


SHORT = "run.duration=30"  # the loop is one text: a short run shows numba's faithfulness


@pytest.mark.slow
@pytest.mark.parametrize("scenario,overrides", VARIANTS)
def test_the_compiled_loop_gives_the_python_loops_bits(monkeypatch, scenario, overrides):
    values = apply_overrides(load_scenario(scenario), [SHORT, *overrides])
    compiled, python = simulate(values), python_run(monkeypatch, values)
    assert compiled.keys() == python.keys()
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name


@pytest.mark.parametrize("fitness", RunningIndex.MONOTONE)
def test_pruning_ends_the_compiled_run_where_the_python_run_ends(monkeypatch, fitness):
    values = apply_overrides(load_scenario("seed000"), ["run.duration=600", "adrc.mu1=700"])
    full = RunningIndex(fitness)
    simulate(values, prune=(full, np.inf))
    limit = full.value / 3
    compiled, python = RunningIndex(fitness), RunningIndex(fitness)
    steps = len(simulate(values, prune=(compiled, limit))["t"])
    assert steps == len(python_run(monkeypatch, values, (python, limit))["t"]) < 12000
    assert np.array_equal(compiled.state, python.state, equal_nan=True)


def test_a_diverging_run_ends_at_the_same_step(monkeypatch):
    values = apply_overrides(load_scenario("seed000"), ["run.duration=300", "adrc.b0=0.001"])
    compiled, python = simulate(values), python_run(monkeypatch, values)
    assert len(compiled["t"]) == len(python["t"]) < 6000
    assert np.array_equal(compiled["speed"], python["speed"], equal_nan=True)


def chunked_run(monkeypatch, values, first_chunk, prune=None):
    """simulate(), the compiled loop called first for `first_chunk` steps, then for
    one step at a time (a chunk aims at no wall time at all)."""
    with monkeypatch.context() as patch:
        patch.setattr(fast_loop, "FIRST_CHUNK", first_chunk)
        patch.setattr(fast_loop, "CHUNK_SECONDS", 0.0)
        return simulate(values, prune=prune)


@pytest.mark.parametrize("scenario,overrides", VARIANTS)
def test_a_run_in_one_step_chunks_gives_the_bits_of_a_run_in_one_call(monkeypatch, scenario,
                                                                       overrides):
    values = apply_overrides(load_scenario(scenario), [SHORT, *overrides])
    whole, chunked = (chunked_run(monkeypatch, values, first) for first in (10**9, 1))
    assert len(whole["t"]) == steps(values)
    for name in whole:
        assert np.array_equal(whole[name], chunked[name], equal_nan=True), name


def test_pruned_and_diverging_runs_end_at_the_same_step_in_chunks(monkeypatch):
    values = apply_overrides(load_scenario("seed000"), ["run.duration=600", "adrc.mu1=700"])
    ends = []
    for first in (10**9, 7):
        running = RunningIndex("itae")
        steps = len(chunked_run(monkeypatch, values, first, (running, 5000.0))["t"])
        ends.append((steps, *running.state))
    assert ends[0] == ends[1] and ends[0][0] < 12000
    diverging = apply_overrides(load_scenario("seed000"), ["run.duration=300", "adrc.b0=0.001"])
    whole, chunked = (chunked_run(monkeypatch, diverging, first) for first in (10**9, 3))
    assert len(whole["t"]) == len(chunked["t"]) < 6000
    assert np.array_equal(whole["speed"], chunked["speed"], equal_nan=True)


COVERED = sorted(scenario_names())


@pytest.mark.parametrize("overrides", [["gpc.prediction=mechanistic"],
                                       ["gpc.prediction=multimodel"],
                                       ["gpc.constrained=false", "gpc.correction=false"],
                                       ["estimator.enabled=true", "plant.mass_factor=1.2",
                                        "plant.resistance_factor=1.3"]])
@pytest.mark.slow
def test_a_kind_without_compiled_steps_gives_the_python_loops_bits(monkeypatch, overrides):
    """A kind registered without steps (a plug-in's) has its controller's own step called
    from the compiled loop (python_steps): here the GPC so registered, for each of its
    models, against the Python loop and against the GPC's compiled steps."""
    values = apply_overrides(load_scenario("seed001-crh380al"), ["run.duration=120",
                                                                 *overrides])
    stepped = simulate(values)
    monkeypatch.setitem(CONTROLLERS.components, "gpc",
                        dataclasses.replace(CONTROLLERS["gpc"], steps=None))
    called, step = [], SteppedController.step
    monkeypatch.setattr(SteppedController, "step",
                        lambda *args: called.append(1) or step(*args))
    compiled, python = simulate(values), python_run(monkeypatch, values)
    assert len(called) == 2 * len(python["t"])  # both loops called the controller's step
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name
        assert np.array_equal(compiled[name], stepped[name], equal_nan=True), name
    assert not python_steps.RUNNING  # the run let go of its controller


@pytest.mark.slow
@pytest.mark.parametrize("scenario", COVERED)
def test_every_shipped_scenario_gives_the_python_loops_bits(monkeypatch, scenario):
    values = load_scenario(scenario)
    values = apply_overrides(values, {"run.duration": min(30.0, values["run.duration"])})
    compiled, python = simulate(values), python_run(monkeypatch, values)
    assert compiled.keys() == python.keys()
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name


@pytest.mark.slow
def test_every_run_of_a_kind_calls_one_compiled_signature():
    """So one compilation per controller kind (setup.sh's, or a tuning's before its
    workers start) serves every compiled run of the checkout but journeys and runs with
    the on-board estimator or the sensors on: lines or open track, time- or
    position-indexed targets, dead time or none. Whatever ran in this process before
    (the count is of the compiled kinds' signatures)."""
    loop.warm()
    for scenario, overrides in VARIANTS:
        values = apply_overrides(load_scenario(scenario), ["run.duration=1", *overrides])
        simulate(values)
        simulate(values, prune=(RunningIndex("max_abs_error"), 1.0))
    for scenario in COVERED:
        simulate(apply_overrides(load_scenario(scenario), ["run.duration=1"]))
    variants = [signature_variant(signature) for signature in fast_loop._steps.signatures
                if "PythonController" not in str(signature)]  # plug-ins share python_steps'
    assert len(variants) == len(set(variants))  # one compilation for each
    kinds = {state for state, _, _, _ in variants}
    assert len(kinds) == len(fast_loop.compiled_kinds())
    assert {journey for _, journey, _, _ in variants} == {False, True}
    assert {estimating for _, _, estimating, _ in variants} == {False, True}
    assert {sensing for _, _, _, sensing in variants} == {False, True}


def signature_variant(signature) -> tuple[str, bool, bool, bool]:
    """(the controller kind's state type, a journey's loop, the estimator's loop, the
    sensors' loop) of a compiled signature of the loop."""
    text = str(signature)
    states = set(re.findall(r"(\w+State)\(", text)) - {
        "LoopState", "ProfileState", "RunningState", "JourneyState", "NominalState",
        "EstimatorState", "OdometryState", "OdometerState", "LocaliserState"}
    assert len(states) == 1, states
    return (states.pop(), "JourneyTable" in text, "EstimatorState" in text,
            "LocaliserState" in text)


def test_warming_takes_any_run_a_tuning_may_start_from():
    for overrides in (["run.period=0.0001"], ["run.period=10"], ["controller.kind=pid"]):
        loop.warm(apply_overrides(load_scenario("seed000"), overrides))


def test_warming_a_run_with_the_estimator_compiles_the_signature_it_calls():
    """The estimator on is a signature of its own: warm() compiles it for the kinds that
    use it (and leaves it off for the others, which refuse it)."""
    values = apply_overrides(load_scenario("seed004-metro-ato"),
                             ["run.duration=1", "estimator.enabled=true"])
    loop.warm(values)
    warmed = len(fast_loop._steps.signatures)
    simulate(values)
    simulate(apply_overrides(values, ["controller.kind=pid"]))
    assert len(fast_loop._steps.signatures) == warmed


def test_the_compiled_loop_checks_the_deadline_between_its_chunks(monkeypatch):
    """A clock that advances one second per reading: the run passes its deadline at
    the sixth check, the sixth one-step chunk."""
    clock = itertools.count()
    monkeypatch.setattr(loop, "time", SimpleNamespace(monotonic=lambda: next(clock)))
    monkeypatch.setattr(fast_loop, "FIRST_CHUNK", 1)
    monkeypatch.setattr(fast_loop, "CHUNK_SECONDS", 0.0)
    with pytest.raises(TimeoutError, match="deadline at step 5$"):
        simulate(load_scenario("seed000"), deadline=4.5)


@pytest.mark.parametrize("overrides,changes", [
    (["profile.approach_step=0.5"], None),  # time-indexed, with the stepped approach
    ([], {10: {"adrc.mu1": 700.0}, 40: {"adrc.mu2": 90.0}}),  # live gains
    (["controller.kind=gpc", "gpc.prediction=mechanistic", "gpc.horizon=2",  # a Python step
      "controller.preview=2"],
     None)])
def test_the_runs_the_python_loop_once_took_alone_run_compiled(monkeypatch, overrides,
                                                                changes):
    """With numba present no run leaves the compiled loop (there is no fallback: a run it
    could not take fails, numba's typing error, instead of running as Python)."""
    values = apply_overrides(load_scenario("seed000"), ["run.duration=10", *overrides])

    def uncompiled(*arguments):
        raise AssertionError("a compiled run went to the Python loop")

    with monkeypatch.context() as patch:
        patch.setattr(fast_loop, "_steps_source", uncompiled)
        compiled = simulate(values, changes=changes)
    python = simulate(values, changes=changes, compiled=False)
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name


def test_a_kind_registered_after_import_joins_the_dispatch(monkeypatch):
    """The steps are found by the type of the kind's state in the registry as it is when
    asked (compiled code asks while compiling): an outside plug-in's kind joins."""
    from typing import NamedTuple

    from ato_nodes.core.control.stepped import ControllerSteps

    class LateState(NamedTuple):
        count: int = 0

    late = ControllerSteps(lambda *arguments: arguments[1], lambda *arguments: None, LateState)
    monkeypatch.setitem(CONTROLLERS.components, "late_kind",
                        SimpleNamespace(kind="late_kind", steps=late))
    assert fast_loop.steps_of(LateState) is late
    assert "late_kind" in fast_loop.compiled_kinds()
    assert fast_loop.controller_start(None, LateState(), 1.0, 0.0, [1.0]) == LateState()


@pytest.mark.parametrize("scenario", ["seed003-maglev", "seed002-hsr", "seed001-excitation"])
def test_a_line_run_in_one_step_chunks_gives_the_bits_of_a_run_in_one_call(monkeypatch,
                                                                            scenario):
    """What the loop carries between chunks on a line: the commands inside the dead time,
    the profile's last position and stair, the traction power."""
    values = apply_overrides(load_scenario(scenario), ["run.duration=100"])
    whole, chunked = (chunked_run(monkeypatch, values, first) for first in (10**9, 1))
    for name in whole:
        assert np.array_equal(whole[name], chunked[name], equal_nan=True), name


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["seed004-metro-ato", "seed002-hsr", "hsr-neutral-ato"])
def test_a_plan_table_gives_the_plans_own_speeds_and_limits_compiled(scenario):
    """PlanTable's interpolation, written out for compiled code, against the plan's
    np.interp and np.searchsorted: at, beside and between the points, beyond both ends."""
    import numba
    from ato_nodes.core.config.context import RunContext
    from ato_nodes.core.targets.profiles import table_limit, table_speed
    plan = RunContext(load_scenario(scenario)).plan
    table = plan.table()
    speed = numba.njit(lambda position: table_speed(table, position))
    limit = numba.njit(lambda position: table_limit(table, position))
    points = table.grid[0]
    positions = np.concatenate([
        np.random.default_rng(1).uniform(points[0] - 10, points[-1] + 10, 20000), points,
        np.nextafter(points, np.inf), np.nextafter(points, -np.inf), [np.inf, -np.inf]])
    for position in positions:
        assert speed(position) == plan.speed(0.0, position), position
        if plan.limits_speed:
            assert limit(position) == plan.limit(position), position


@pytest.mark.slow
def test_the_compiled_interpolation_is_numpys_on_uneven_points():
    """interpolated() and cell_of(), as compiled code runs them, against np.interp and
    np.searchsorted on points far from evenly spaced (the search starts where even points
    would put x): at, beside and between the points, beyond both ends, NaN."""
    import numba
    from ato_nodes.core.targets.profiles import cell_of, interpolated
    rng = np.random.default_rng(2)
    points = np.cumsum(rng.exponential(1.0, 400) ** 3)  # dense stretches and wide gaps
    values = rng.normal(size=len(points))
    interpolate = numba.njit(lambda x: interpolated(x, points, values))
    cell = numba.njit(lambda x: cell_of(points, x))
    positions = np.concatenate([
        rng.uniform(points[0] - 10, points[-1] + 10, 20000), points,
        np.nextafter(points, np.inf), np.nextafter(points, -np.inf), [np.inf, -np.inf]])
    for x in positions:
        assert interpolate(x) == np.interp(x, points, values), x
        assert cell(x) == np.searchsorted(points, x, side="right") - 1, x
    assert np.isnan(interpolate(np.nan)) and cell(np.nan) == -1
