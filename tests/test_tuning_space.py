"""What tune.py tunes: the controller kinds' default search spaces, names the run does not
use refused, the warning for line runs without requirements (fast, in-process)."""

import csv
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.scoring.indices import RunningIndex
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.studies.tuning import SearchSpace, Tuner, TuningSettings
from commands import invocation

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("kind", sorted(CONTROLLERS.components))
def test_every_controller_kind_has_a_default_search_space_inside_the_schema(kind):
    values = apply_overrides(load_scenario("seed000"), [f"controller.kind={kind}"]) \
        if kind != "gpc" else load_scenario("seed001-crh380al")
    space = SearchSpace.default(values)
    component = CONTROLLERS[kind]
    assert space.names == tuple(name for name, _, _ in component.search_space)
    assert all(name in {spec.name for spec in component.parameters} for name in space.names)


def test_a_parameter_of_another_controller_kind_is_refused():
    values = load_scenario("seed004-metro")  # discrete_adrc
    with pytest.raises(ScenarioError, match=r"--params: adrc.mu1 belongs to controller kind "
                                            r"han_adrc; this run uses discrete_adrc \(its "
                                            r"parameters are dadrc.\*\)"):
        SearchSpace.parse(["adrc.mu1=100:1000"], values)
    assert SearchSpace.parse(["dadrc.b1=1:300,controller.max_rate=10:100"], values).names == (
        "dadrc.b1", "controller.max_rate")  # its own and shared parameters pass


@pytest.mark.slow
def test_tune_without_params_tunes_the_default_space_and_warns_on_a_line(tmp_path):
    result = subprocess.run(
        [*invocation("tune"), "--algorithm", "pso",
         "--scenario", "seed004-metro", "--set", "run.duration=3", "--in-process",
         "--evaluations", "4", "--population", "2", "--out", tmp_path / "t"],
        capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "tuning the default search space: dadrc.b01=0.1:2.5" in result.stdout
    assert "warning: tuning on a line without --require" in result.stderr
    refused = subprocess.run(
        [*invocation("tune"), "--scenario", "seed004-metro",
         "--params", "pid.kp=1:10", "--in-process", "--out", tmp_path / "u"],
        capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1
    assert "pid.kp belongs to controller kind pid" in refused.stderr


@pytest.mark.slow
def test_best_yaml_is_the_base_scenario_and_its_changes_and_history_is_plain_numbers(tmp_path):
    out = tmp_path / "t"
    result = subprocess.run(
        [*invocation("tune"), "--algorithm", "pso",
         "--scenario", "seed004-metro-ato", "--set", "run.duration=4", "--in-process",
         "--params", "ladrc.omega_c=0.3:6", "--require", "abs_stopping_error<=3000",
         "--evaluations", "4", "--population", "2", "--quiet", "--out", out],
        capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert result.returncode == 0, result.stderr
    text = (out / "best.yaml").read_text()
    assert "base: seed004-metro-ato" in text and str(ROOT) not in text.split("\n", 2)[2]
    summary = json.loads((out / "summary.json").read_text())
    expected = apply_overrides(load_scenario("seed004-metro-ato"),
                               ["run.duration=4",
                                f"ladrc.omega_c={summary['best_params']['ladrc.omega_c']!r}"])
    assert load_scenario(str(out / "best.yaml")) == expected
    best = out / "best.yaml"
    assert f"run the best: python scripts/run_stack.py --scenario {best}" in result.stdout
    with (out / "history.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    import pandas
    assert all(dtype.kind in "if" for dtype in pandas.read_csv(out / "history.csv").dtypes)
    cells = [[float(value) for value in row.values()] for row in rows]  # plain numbers
    best = [row[2] for row in cells]
    assert len(rows) == 2 and best == sorted(best, reverse=True)  # best so far never rises


@pytest.mark.parametrize("name", RunningIndex.MONOTONE)
def test_the_running_index_ends_at_the_scorers_value(name):
    values = apply_overrides(load_scenario("seed004-metro-ato"), ["run.duration=30"])
    series = simulate(values)
    running = RunningIndex(name)
    trace = [running.add(t, r - v) for t, r, v in zip(series["t"], series["target"],
                                                        series["speed"], strict=True)]
    assert trace == sorted(trace)  # only grows
    assert trace[-1] == pytest.approx(score_series(series, values)[name], rel=1e-12)


@pytest.mark.parametrize("algorithm", ["pso", "bas-pso"])
def test_pruning_leaves_the_tuning_result_as_it_is(tmp_path, algorithm):
    values = apply_overrides(load_scenario("seed000"), ["run.duration=60"])
    space = SearchSpace.parse(["adrc.mu1=600:60000,adrc.mu2=550:55000"], values)
    results = {}
    for prune in (True, False):
        settings = TuningSettings(algorithm, "seed000", space, evaluations=60, seed=4,
                                  workers=2, in_process=True, options={"population_size": 6},
                                  prune=prune)
        out = tmp_path / f"prune-{prune}"
        result = Tuner(values, settings, out, progress=False).run()
        records = [json.loads(line)
                   for line in (out / "evaluations.jsonl").read_text().splitlines()]
        results[prune] = (result, records, json.loads((out / "summary.json").read_text()))
    (cut, cut_log, cut_summary), (whole, whole_log, _) = results[True], results[False]
    assert cut.best_f == whole.best_f and np.array_equal(cut.best_x, whole.best_x)
    assert np.array_equal(cut.trace("best_f"), whole.trace("best_f"))
    exact = {r["index"]: r["fitness"] for r in whole_log}
    pruned = [r for r in cut_log if r["status"] == "pruned"]
    assert pruned and cut_summary["pruned_evaluations"] == len(pruned)
    for record in pruned:  # a lower bound of the candidate's true fitness
        assert record["fitness"] <= exact[record["index"]] * (1 + 1e-9)
