"""The real train apart from the nominal one the ATO knows, and the robustness script."""

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.stages import ControllerStage, PlantStage
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.config.schema import NodeValues
from commands import invocation

ROOT = Path(__file__).resolve().parents[1]
FACTORS = ("plant.mass_factor", "plant.resistance_factor", "plant.lag_factor")


def metro(*overrides):
    return apply_overrides(load_scenario("seed004-metro"), ["run.duration=30", *overrides])


def test_the_real_train_factors_change_the_plant_and_not_what_the_controller_knows():
    values = metro("plant.mass_factor=1.3", "plant.resistance_factor=1.2", "plant.lag_factor=0.7")
    plant = PlantStage(NodeValues("plant", values))
    nominal = PlantStage(NodeValues("plant", metro()))
    assert plant.params.mass == pytest.approx(1.3 * nominal.params.mass)
    assert plant.params.davis_c == pytest.approx(1.2 * nominal.params.davis_c)
    assert plant.params.actuator_lag == pytest.approx(0.7 * nominal.params.actuator_lag)
    controller = NodeValues("controller", values)
    for name in FACTORS:  # the plant node's alone: the controller cannot read them
        with pytest.raises(ScenarioError, match="not declared"):
            controller[name]
    assert ControllerStage(controller).context.train == ControllerStage(
        NodeValues("controller", metro())).context.train
    assert not np.array_equal(simulate(values)["speed"], simulate(metro())["speed"])


def script(*args):
    return subprocess.run([*invocation("robustness"),
                           *map(str, args)], capture_output=True, text=True, cwd=ROOT,
                          timeout=120)


@pytest.mark.slow
def test_the_robustness_script_draws_inside_its_ranges_and_reports_the_worst(tmp_path):
    result = script("seed004-metro", "--samples", "3", "--set", "run.duration=20",
                    "--mass", "0.9:1.1", "--out", tmp_path / "r")
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "r" / "robustness.json").read_text())
    samples = report["samples"]
    assert len(samples) == 3 and len({s["plant.noise_seed"] for s in samples}) == 3
    assert all(0.9 <= s["plant.mass_factor"] <= 1.1 for s in samples)
    assert all(0.8 <= s["plant.resistance_factor"] <= 1.2 for s in samples)
    worst = report["summary"]["max_abs_error_kmh"]["worst"]
    assert worst == max(s["max_abs_error_kmh"] for s in samples)
    assert (tmp_path / "r" / "robustness.png").stat().st_size > 0


@pytest.mark.parametrize("args, words", [
    (["--mass", "1.3:0.9"], "0 < LOW <= HIGH"), (["--lag", "x"], "LOW:HIGH"),
    (["--mass", "0.01:1"], "out of range")])
def test_bad_robustness_ranges_are_one_line(tmp_path, args, words):
    result = script("seed004-metro", *args, "--out", tmp_path / "r")
    assert result.returncode == 2 and words in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_timing_point_journey_counts_its_timing_points_and_others_keep_their_columns():
    from ato_nodes.results.journeys import TIMING_MISSED
    from ato_nodes.studies.robustness import (COLUMNS, OVERSPEED, SENSOR_SEED, WITHIN,
                                              study_columns, summarise)
    assert study_columns(load_scenario("seed004-metro")) == COLUMNS  # no journey, no sensors
    on_board = list(study_columns(load_scenario("seed004-metro-line")))  # the sensors' seed
    assert on_board == [*COLUMNS, SENSOR_SEED, "overrun", OVERSPEED]
    columns = list(study_columns(load_scenario("stgallen-wil-journey")))
    assert columns == [*COLUMNS, TIMING_MISSED]
    kept = next(text for key, _, text in WITHIN if key == TIMING_MISSED)
    values = np.zeros((3, len(columns)))
    values[:, columns.index(TIMING_MISSED)] = [0.0, 1.0, 0.0]
    _, within = summarise(values, np.ones(values.shape, dtype=bool), columns)
    assert within[kept] == 2
    _, within = summarise(values[:, :-1], np.ones((3, len(COLUMNS)), dtype=bool),
                          list(COLUMNS))
    assert kept not in within
