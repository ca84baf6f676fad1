"""The compiled loop (core/fast_loop.py) against the Python loop, bit for bit."""

import numpy as np
import pytest

from ato_nodes.core import fast_loop, kernels
from ato_nodes.core.indices import RunningIndex
from ato_nodes.core.loop import simulate
from ato_nodes.core.scenario import apply_overrides, load_scenario

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
]


def python_run(monkeypatch, values, prune=None):
    with monkeypatch.context() as patch:
        patch.setattr(fast_loop, "AVAILABLE", False)
        return simulate(values, prune=prune)


@pytest.mark.parametrize("scenario,overrides", VARIANTS)
def test_the_compiled_loop_gives_the_python_loops_bits(monkeypatch, scenario, overrides):
    values = apply_overrides(load_scenario(scenario), ["run.duration=300", *overrides])
    assert fast_loop.covers(*stages(values))
    compiled, python = simulate(values), python_run(monkeypatch, values)
    assert compiled.keys() == python.keys()
    for name in python:
        assert np.array_equal(compiled[name], python[name]), name


@pytest.mark.parametrize("fitness", RunningIndex.MONOTONE)
def test_pruning_ends_the_compiled_run_where_the_python_run_ends(monkeypatch, fitness):
    values = apply_overrides(load_scenario("seed000"), ["run.duration=600", "adrc.mu1=700"])
    full = RunningIndex(fitness)
    simulate(values, prune=(full, np.inf))
    limit = full.value / 3
    compiled, python = RunningIndex(fitness), RunningIndex(fitness)
    steps = len(simulate(values, prune=(compiled, limit))["t"])
    assert steps == len(python_run(monkeypatch, values, (python, limit))["t"]) < 12000
    assert np.array_equal([compiled.value, compiled.last_t, compiled.last_w],
                          [python.value, python.last_t, python.last_w], equal_nan=True)


def test_a_diverging_run_ends_at_the_same_step(monkeypatch):
    values = apply_overrides(load_scenario("seed000"), ["run.duration=300", "adrc.b0=0.001"])
    compiled, python = simulate(values), python_run(monkeypatch, values)
    assert len(compiled["t"]) == len(python["t"]) < 6000
    assert np.array_equal(compiled["speed"], python["speed"], equal_nan=True)


def test_runs_it_does_not_cover_take_the_python_loop():
    for scenario in ("seed004-metro", "seed003-maglev", "seed000-ato", "hsr-neutral"):
        assert not fast_loop.covers(*stages(load_scenario(scenario)))


def stages(values):
    from ato_nodes.core.loop import ControllerStage, PlantStage, ProfileStage
    from ato_nodes.core.schema import NodeValues
    return (ProfileStage(NodeValues("profile", values)), PlantStage(NodeValues("plant", values)),
            ControllerStage(NodeValues("controller", values)), None)
