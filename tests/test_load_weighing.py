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
from ato_nodes.core.run.scoring import run_line, score_series
from ato_nodes.core.run.stages import ControllerStage, PlantStage
from ato_nodes.core.train.line import load_line

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


def test_a_reading_above_the_crush_load_is_clipped_to_it():
    seed = next(seed for seed in range(100) if load_weighing(1.28, 0.03, seed) > 1.3)
    read = maglev("plant.mass_factor=1.28", f"train.load_weighing_seed={seed}",
                  "train.load_weighing_max=0")["train.mass_reading"]
    assert read == load_weighing(1.28, 0.03, seed) > 1.3
    clipped = maglev("plant.mass_factor=1.28", f"train.load_weighing_seed={seed}",
                     "train.load_weighing_max=1.3")
    assert clipped["train.mass_reading"] == 1.3
    below = maglev("plant.mass_factor=1.1", "train.load_weighing_max=1.3")
    assert below["train.mass_reading"] == load_weighing(1.1, 0.03, 0)


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
    top = float(nominal.caps.max())  # the fastest curves: both plan 402 s below them
    assert heavy.run_time(top) > nominal.run_time(top) + 1.0
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
    wider = "profile.ato.margin=1.3889"  # 5 km/h under the limits: 405 s at mass 1.3
    curve = plan(maglev("train.load_weighing=false", "train.mass_reading=1.3", wider))
    assert curve.cruise == float(curve.caps.max())
    assert "402 s cannot be met" in curve.notice and "minimum-time" in curve.notice
    assert "\n" not in curve.notice
    papers = plan(load_scenario("seed004-metro"))  # the papers' curve: no notice, as before
    assert papers.notice is None and papers.cruise == float(papers.caps.max())


@pytest.mark.parametrize("scenario", ["seed004-metro-ato", MAGLEV, "hsr-neutral-ato"])
def test_the_shipped_ato_scenarios_plan_their_lines_time(scenario):
    values = prepare(scenario, [])
    curve = plan(values)
    planned = load_line(values["line.file"]).planned_run_time
    assert curve.notice is None and curve.planned_run_time == pytest.approx(planned, abs=2.0)


def planned_force(curve, speeds, train, line):
    """The specific force `speeds` on the curve's grid plan in each cell, N/kN
    (+ traction), and whether the pantograph is in a neutral section there."""
    x, v = curve.positions, speeds
    rate = np.diff(v ** 2) / (2.0 * np.diff(x))
    force = np.array([rate[i] / train.xi + train.resistance(v[i])
                      + line.additional_resistance(x[i], train.length) for i in range(len(rate))])
    neutral = np.array([line.in_neutral_section(p - train.pantograph_offset) for p in x[:-1]])
    return force, neutral


@pytest.mark.slow
def test_the_capped_curve_falls_where_the_share_cannot_hold_the_cruise_speed():
    # the curve without the coasting past its neutral sections, whose cruise is a little
    # higher: the grade's cell at 15211.5 m plans about 0.5 N/kN over the share then (0.518
    # with the ramped departure's on-time count), against 5 and more with the cap alone
    values = prepare("hsr-neutral-ato", ["train.load_weighing=false", "train.mass_reading=1.3",
                                         "profile.ato.neutral_runout=0"])
    context = RunContext(NodeValues("profile", values))
    curve, train, line = context.plan, context.train, context.line
    force, _ = planned_force(curve, curve.curve(curve.cruise), train, line)
    share = np.array([curve.cells.share * train.force_limits(v)[1] for v in curve.speeds[:-1]])
    assert curve.cruise < float(curve.caps.max())
    assert np.max(force - share) < 1.0  # the 15 per mille grade at 224 km/h: it falls
    capped = np.minimum(curve.feasible, curve.cruise)  # the cap alone held it there
    force, _ = planned_force(curve, capped, train, line)
    assert np.max(force - share) > 5.0


@pytest.mark.slow
def test_the_capped_curve_coasts_through_neutral_sections():
    values = prepare("hsr-neutral-ato", [])
    context = RunContext(NodeValues("profile", values))
    curve, train, line = context.plan, context.train, context.line
    assert curve.cruise < float(curve.caps.max()) - 5.0  # capped well below the limits
    force, neutral = planned_force(curve, curve.speeds, train, line)
    assert neutral.sum() > 1000  # both sections, 0.5 m cells
    assert np.all(force[neutral] <= 1e-6)  # no traction planned inside a section
    assert np.max(force[~neutral]) > 5.0  # where it is powered, it drives
    for cruise in (curve.cruise - 20.0 / 3.6, float(curve.caps.max())):
        force, _ = planned_force(curve, curve.curve(cruise), train, line)
        assert np.all(force[neutral] <= 1e-6)
    # the cap alone held the cruise speed through the up-grade section: traction
    capped = np.minimum(curve.feasible, curve.cruise)
    force, _ = planned_force(curve, capped, train, line)
    assert np.max(force[neutral]) > 5.0


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


def test_a_run_timetabled_to_another_time_plans_to_it_and_is_judged_against_it():
    # metro-interstation.yaml plans 165 s; a timetable with 10 s more for the same line
    values = prepare("seed004-metro-ato", ["line.planned_run_time=175"])
    curve = plan(values)
    assert curve.notice is None and curve.planned_run_time == pytest.approx(175.0, abs=2.0)
    assert plan(prepare("seed004-metro-ato")).planned_run_time < 170.0
    indices = score_series(simulate(values), values)
    assert abs(indices["running_time_error"]) <= 2.0
    assert indices["arrival_time"] - indices["running_time_error"] == pytest.approx(175.0)


def test_a_bag_is_judged_against_the_time_it_was_run_to_and_one_without_it_the_files():
    values = prepare("seed004-metro-ato", ["line.planned_run_time=175"])
    assert run_line(values).planned_run_time == 175.0
    before = {name: value for name, value in values.items() if name != "line.planned_run_time"}
    assert run_line(before).planned_run_time == 165.0  # a bag recorded before the parameter
    assert run_line(prepare("seed004-metro-ato")).planned_run_time == 165.0


def test_a_negative_planned_time_is_refused_in_one_line():
    with pytest.raises(ScenarioError, match="line.planned_run_time") as refused:
        prepare("seed004-metro-ato", ["line.planned_run_time=-5"])
    assert "\n" not in str(refused.value)
