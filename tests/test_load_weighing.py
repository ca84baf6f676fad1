"""The load weighing at departure (train.load_weighing: the ATO's train at the weighed
mass) and the on-time ato curve (profile.ato.on_time)."""

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, prepare
from ato_nodes.core.config.schema import NodeValues
from ato_nodes.core.control.estimation import load_weighing
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.run.stages import ControllerStage, PlantStage

MAGLEV = "seed003-maglev-ato"  # weighs its load, on time; its 55 per mille grades bind


def maglev(*overrides):
    return prepare(MAGLEV, list(overrides))


def plan(values):
    return RunContext(NodeValues("profile", values)).plan


def test_the_reading_is_the_seeded_load_weighing_of_the_real_train():
    values = maglev("plant.mass_factor=1.2", "train.load_weighing_seed=7")
    assert values["train.mass_reading"] == load_weighing(1.2, 0.03, 7)
    assert maglev("plant.mass_factor=1.2", "train.load_weighing_seed=7") == values
    assert maglev("plant.mass_factor=1.2", "train.load_weighing_seed=8")[
        "train.mass_reading"] != values["train.mass_reading"]
    exact = maglev("plant.mass_factor=1.2", "train.load_weighing_error=0")
    assert exact["train.mass_reading"] == 1.2
    errors = np.array([load_weighing(1.2, 0.03, seed) / 1.2 - 1.0 for seed in range(400)])
    assert abs(errors.mean()) < 0.006 and 0.025 < errors.std() < 0.035


def test_the_reading_follows_an_override_of_the_real_train_and_is_off_by_default():
    base = maglev()
    heavy = apply_overrides(base, {"plant.mass_factor": 1.25})  # as robustness.py does
    assert heavy["train.mass_reading"] == load_weighing(1.25, 0.03, 0)
    paper = load_scenario("seed003-maglev")
    assert not paper["train.load_weighing"] and paper["train.mass_reading"] == 1.0
    assert apply_overrides(paper, ["plant.mass_factor=1.3"])["train.mass_reading"] == 1.0


def test_the_ato_knows_the_weighed_train_and_the_plant_is_the_real_one():
    values = maglev("plant.mass_factor=1.3", "train.load_weighing_error=0")
    controller = ControllerStage(NodeValues("controller", values))
    nominal = ControllerStage(NodeValues("controller", maglev("train.load_weighing=false")))
    assert controller.context.train.mass == 1.3 * nominal.context.train.mass
    assert controller.controller.settings.model.train.envelope.weight == pytest.approx(
        1.3 * nominal.controller.settings.model.train.envelope.weight)
    assert PlantStage(NodeValues("plant", values)).params.mass == 1.3 * 100.0
    assert plan(values).feasible is not None


def test_a_heavy_trains_plan_is_slower_where_the_envelope_binds_and_a_light_ones_keeps_the_limits():
    off = ("train.load_weighing=false", "profile.ato.on_time=false")
    nominal = plan(maglev(*off))
    heavy = plan(maglev(*off, "train.mass_reading=1.3"))
    light = plan(maglev(*off, "train.mass_reading=0.85"))
    assert np.all(heavy.feasible <= nominal.feasible + 1e-12)
    assert np.sum(heavy.feasible < nominal.feasible - 0.5) > 100  # metres of grades, 0.5 m/s
    assert heavy.planned_run_time > nominal.planned_run_time + 1.0
    # a light train is planned as the nominal one: the command limits are the nominal's
    assert np.array_equal(light.speeds, nominal.speeds)
    light_values = NodeValues("controller", maglev(*off, "train.mass_reading=0.85"))
    assert RunContext(light_values).train == RunContext(NodeValues("controller",
                                                                   maglev(*off))).train
    assert np.all(light.speeds <= light.limits - light.margin / 2 + 1e-12)
    gain = np.diff(light.feasible ** 2) / (2.0 * np.diff(light.positions))
    assert np.all(gain <= light.acceleration + 1e-9)  # never more than the planned rate


def test_the_on_time_curve_plans_the_lines_time_and_arrives_within_two_seconds():
    closer = "profile.ato.margin=0.5"  # 1.39 m/s under the limits misses 402 s by 0.8 s
    values = maglev(closer)
    curve = plan(values)
    assert curve.notice is None and curve.cruise < float(curve.caps.max())
    assert curve.planned_run_time == pytest.approx(curve.line.planned_run_time, abs=1e-6)
    indices = score_series(simulate(values), values)
    assert abs(indices["running_time_error"]) <= 2.0
    own = plan(maglev(closer, "profile.ato.on_time=false"))
    assert own.cruise < curve.cruise  # the curve's own time left out the departure and stop


def test_a_planned_time_the_fastest_curve_misses_is_one_line_and_the_curve_runs_at_the_limits():
    curve = plan(maglev("train.load_weighing=false", "train.mass_reading=1.3"))
    assert curve.cruise == float(curve.caps.max())
    assert "402 s cannot be met" in curve.notice and "minimum-time" in curve.notice
    assert "\n" not in curve.notice
    papers = plan(load_scenario("seed004-metro"))  # the papers' curve: no notice, as before
    assert papers.notice is None and papers.cruise == float(papers.caps.max())


@pytest.mark.parametrize("overrides, words", [
    (["train.load_weighing_error=0.9"], "train.load_weighing_error = 0.9 is out of range"),
    (["train.load_weighing=1"], "train.load_weighing must be true or false"),
    (["train.mass_reading=1.1"], "train.mass_reading is the load weighing's reading"),
    (["train.load_weighing_seed=-1"], "out of range"),
    (["profile.ato.on_time=maybe"], "profile.ato.on_time must be true or false")])
def test_bad_load_weighing_parameters_are_one_line(overrides, words):
    with pytest.raises(ScenarioError, match=words) as raised:
        maglev(*overrides)
    assert "\n" not in str(raised.value)
