"""The tuner: search space, equal fitness in both modes, faulty candidates, resume."""

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.launcher.launch import node_processes as launched_nodes
from ato_nodes.studies.tuning import (PENALTY, SearchSpace, Tuner, TuningSettings,
                                      evaluate_in_process, evaluate_in_stack)
from commands import invocation

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
TUNE = [*invocation("tune")]


def short(duration):
    return apply_overrides(load_scenario("seed000"), [f"run.duration={duration}"])


def node_processes():
    """Node processes this test process started and that still run (other runs on the
    machine are not this test's business)."""
    return sorted(launched_nodes(os.getpid()).values())


def test_search_space_parsing():
    space = SearchSpace.parse(["adrc.mu1=100:20000,adrc.beta1=10:3000", "plant.substeps=1:8"])
    assert space.names == ("adrc.mu1", "adrc.beta1", "plant.substeps")
    assert space.overrides(np.array([150.0, 20.0, 2.6])) == {
        "adrc.mu1": 150.0, "adrc.beta1": 20.0, "plant.substeps": 3}
    assert list(space.start(short(1))) == [6000.0, 1200.0, 1.0]
    for bad, problem in [("adrc.mu1=5", "name=low:high"), ("adrc.mu9=1:2", "not a numeric"),
                         ("adrc.mu1=3:1", "low < high"), ("adrc.r0=-5:1", "out of range"),
                         ("controller.kind=1:2", "not a numeric")]:
        with pytest.raises(ScenarioError, match=problem):
            SearchSpace.parse([bad])


def test_a_candidate_scores_the_same_in_process_and_through_the_stack(tmp_path):
    values, candidate = short(5), {"adrc.mu1": 7000.0, "adrc.beta1": 900.0}
    in_process = evaluate_in_process(values, candidate, "itae", 0)
    stack = evaluate_in_stack(values, candidate, "itae", 0, tmp_path / "bag", timeout=120)
    assert in_process.status == stack.status == "ok"
    assert stack.fitness == pytest.approx(in_process.fitness, rel=1e-9)
    assert stack.indices["max_abs_error"] == pytest.approx(in_process.indices["max_abs_error"],
                                                           rel=1e-9)


def test_diverging_candidate_is_penalised_in_process():
    record = evaluate_in_process(short(20), {"adrc.b0": 0.001}, "itae", 3)
    assert record.status == "diverged" and record.fitness == PENALTY


def test_crashing_and_hanging_candidates_are_penalised_logged_and_cleaned_up(tmp_path):
    faults = {1: "controller:crash:20", 2: "plant:hang:20"}

    def evaluate_with_faults(values, overrides, fitness, index):
        if index in faults:
            values = apply_overrides(values, {"run.fault": faults[index]})
        return tuner._evaluate_in_stack(values, overrides, fitness, index)

    settings = TuningSettings("pso", "seed000", SearchSpace.parse(["adrc.mu1=1000:10000"]),
                              evaluations=4, seed=3, workers=2, timeout=8.0,
                              options={"population_size": 2})
    tuner = Tuner(short(2), settings, tmp_path, evaluate=evaluate_with_faults, progress=False)
    result = tuner.run()
    lines = (tmp_path / "evaluations.jsonl").read_text().splitlines()
    records = {r["index"]: r for r in map(json.loads, lines)}
    assert sorted(records) == [0, 1, 2, 3]
    assert records[1]["status"] == "failed" and "controller" in records[1]["message"]
    assert records[2]["status"] == "timeout"
    assert records[1]["fitness"] == records[2]["fitness"] == PENALTY
    assert records[0]["status"] == records[3]["status"] == "ok"
    assert result.best_f < PENALTY
    assert (tmp_path / "best.yaml").exists() and (tmp_path / "convergence.png").exists()
    assert not any((tmp_path / "runs").iterdir())  # scored candidates' bags are not kept
    assert node_processes() == []


def test_candidate_bags_are_kept_when_asked(tmp_path):
    settings = TuningSettings("pso", "seed000", SearchSpace.parse(["adrc.mu1=1000:10000"]),
                              evaluations=2, seed=3, workers=1, timeout=60.0,
                              options={"population_size": 2}, keep_bags=True)
    Tuner(short(1), settings, tmp_path, progress=False).run()
    kept = sorted(path.name for path in (tmp_path / "runs").iterdir())
    assert kept == ["candidate-00000", "candidate-00001"]
    assert (tmp_path / "runs" / "candidate-00000" / "metadata.yaml").exists()


def test_interrupted_tuning_resumes_to_the_uninterrupted_result(tmp_path):
    common = ["--algorithm", "bas-pso", "--in-process", "--set", "run.duration=30",
              "--params", "adrc.mu1=1000:12000,adrc.mu2=1000:12000", "--evaluations", "60",
              "--population", "4", "--seed", "11", "--quiet"]
    whole = subprocess.run([*TUNE, *common, "--out", str(tmp_path / "whole")],
                           capture_output=True, text=True, timeout=300)
    assert whole.returncode == 0, whole.stderr

    out = tmp_path / "interrupted"
    log = out / "evaluations.jsonl"
    process = subprocess.Popen([*TUNE, *common, "--out", str(out)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and (not log.exists()
                                           or len(log.read_text().splitlines()) < 15):
        time.sleep(0.02)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    logged = len(log.read_text().splitlines())
    assert 15 <= logged < 60

    resumed = subprocess.run([*TUNE, *common, "--out", str(out), "--resume"],
                             capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    first = json.loads((tmp_path / "whole" / "summary.json").read_text())
    second = json.loads((out / "summary.json").read_text())
    assert second["best_params"] == first["best_params"]
    assert second["best_fitness"] == first["best_fitness"]
    assert (out / "history.csv").read_text() == (tmp_path / "whole" / "history.csv").read_text()
    assert len(log.read_text().splitlines()) == 60


def test_bad_tuning_input_is_one_line_and_exit_2(tmp_path):
    result = subprocess.run([*TUNE, "--params", "adrc.mu1=9:1", "--out", str(tmp_path / "x")],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0 and "low < high" in result.stderr


def test_requirements_rank_infeasible_runs_after_feasible_ones_by_how_far_they_miss():
    from ato_nodes.studies.tuning import INFEASIBLE, Objective, Requirement
    objective = Objective("j", (Requirement.parse("abs_stopping_error<=0.3"),
                                Requirement.parse("overspeed_time<=0")))
    feasible = {"j_seed004": 900.0, "abs_stopping_error": 0.2, "overspeed_time": 0.0}
    near = {**feasible, "j_seed004": 70.0, "abs_stopping_error": 0.5}
    far = {**near, "abs_stopping_error": 2600.0}
    assert objective.score(feasible) == (900.0, "ok", "")
    near_value, status, message = objective.score(near)
    assert status == "infeasible" and "abs_stopping_error 0.5 > 0.3" in message
    assert INFEASIBLE < near_value < objective.score(far)[0] < PENALTY
    assert objective.score({**feasible, "overspeed_time": 2.0})[0] > INFEASIBLE
    assert objective.score({"j_seed004": float("nan")})[1] == "diverged"
    with pytest.raises(ScenarioError, match="INDEX<=VALUE"):
        Requirement.parse("abs_stopping_error<0.3")
    with pytest.raises(ScenarioError, match="did you mean abs_stopping_error"):
        Requirement.parse("abs_stoping_error<=0.3")


def test_a_tuning_with_a_requirement_never_picks_the_train_that_stays_at_the_platform(tmp_path):
    """Without the stop requirement, J rewards a metro controller that never moves
    (the position-indexed target is 0.3 m/s where it stands)."""
    from ato_nodes.studies.tuning import Objective, Requirement
    values = apply_overrides(load_scenario("seed004-metro"), ["run.duration=200"])
    parked = {"dadrc.b1": 0.0, "dadrc.b2": 0.0, "dadrc.b03": 0.0}  # no command ever builds up
    moving = {}
    plain, required = Objective("j"), Objective("j", (Requirement("abs_stopping_error", 0.5),))
    parked_plain = evaluate_in_process(values, parked, plain, 0)
    moving_plain = evaluate_in_process(values, moving, plain, 1)
    assert parked_plain.indices["abs_stopping_error"] > 2000
    assert parked_plain.fitness < moving_plain.fitness  # the degenerate optimum
    assert evaluate_in_process(values, parked, required, 0).status == "infeasible"
    assert evaluate_in_process(values, parked, required, 0).fitness > \
        evaluate_in_process(values, moving, required, 1).fitness
