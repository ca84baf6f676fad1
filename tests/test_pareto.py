"""Several objectives at once: the optimizer (pymoo's NSGA-II/III behind one call), the
front and what it is judged by, the tuner's outputs and resume, and tune.py's refusals."""

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.optimizers.pareto import (attainment, hypervolume, knee, minimize_pareto,
                                              nondominated, pseudo_weight_choice)
from ato_nodes.core.scoring.catalogue import Requirement, objective_index
from ato_nodes.studies.pareto_tuning import Choice, ParetoTuner
from ato_nodes.studies.robustness import RANGES, draw_train
from ato_nodes.studies.train_spread import TrainSpread, evaluate_over_trains
from ato_nodes.studies.tuning import (PENALTY, Evaluation, Objectives, SearchSpace,
                                      TuningSettings, evaluate_in_process)
from commands import invocation

ROOT = Path(__file__).resolve().parents[1]


def constrained(X):
    """ZDT1 on six variables (its front f2 = 1 - sqrt(f1) where x2..x6 are 0), f1 >= 0.1
    required (G <= 0)."""
    g = 1.0 + 9.0 * X[:, 1:].mean(axis=1)
    return np.column_stack([X[:, 0], g * (1.0 - np.sqrt(X[:, 0] / g))]), (0.1 - X[:, 0])[:, None]


@pytest.mark.parametrize("algorithm", ["nsga2", "nsga3"])
def test_the_optimizer_is_reproducible_within_budget_and_beats_random_search(algorithm):
    box = (np.zeros(6), np.ones(6))
    start = np.full(6, 0.5)
    runs = [minimize_pareto(algorithm, constrained, *box, 610, 4, objectives=2,
                            constraints=1, x0=start, population_size=24) for _ in range(2)]
    first = runs[0]
    assert np.array_equal(first.X, runs[1].X) and np.array_equal(first.F, runs[1].F)
    assert len(first.X) == 600 and first.generation[-1] == 610 // 24 - 1
    assert list(first.X[0]) == list(start)  # the scenario's own values are asked first
    # feasibility first: once feasible candidates are found, the front is all feasible
    assert np.all(first.X[first.feasible, 0] >= 0.1) and not np.all(first.feasible)
    reference = np.array([1.1, 4.0])
    found = first.F[first.feasible]
    X = np.random.default_rng(4).uniform(0.0, 1.0, (600, 6))
    F, G = constrained(X)
    drawn = F[G[:, 0] <= 0.0]
    volume = hypervolume(found[nondominated(found)], reference)
    assert volume > 1.2 * hypervolume(drawn[nondominated(drawn)], reference)
    assert volume < 3.75  # the true front's, 3.7454
    other_seed = minimize_pareto(algorithm, constrained, *box, 96, 5, objectives=2,
                                 constraints=1, population_size=24)
    assert not np.array_equal(other_seed.X, first.X[:96])


def test_the_front_its_hypervolume_knee_and_pseudo_weights():
    F = np.array([[0.0, 1.0], [0.5, 0.5], [1.0, 0.0], [0.6, 0.6], [0.5, 0.5]])
    assert list(nondominated(F)) == [True, True, True, False, True]  # duplicates kept
    front = F[nondominated(F)]
    # unions of rectangles up to (2, 2): 2*1 + 1.5*1.5 + 1*2 less the overlaps
    assert hypervolume(front, np.array([2.0, 2.0])) == pytest.approx(3.25)
    assert hypervolume(np.array([[3.0, 0.0]]), np.array([2.0, 2.0])) == 0.0
    assert list(front[knee(front)]) == [0.5, 0.5]
    assert list(front[pseudo_weight_choice(front, np.array([0.9, 0.1]))]) == [0.0, 1.0]
    assert list(front[pseudo_weight_choice(front, np.array([1.0, 9.0]))]) == [1.0, 0.0]


def test_attainment_surfaces_count_every_run_a_front_or_not():
    one, other = np.array([[0.0, 1.0], [1.0, 0.0]]), np.array([[0.5, 0.5]])
    surfaces = attainment([one, other], (50.0, 100.0))
    # half the runs: every point either reached; both: the corners both dominate
    assert sorted(map(tuple, surfaces[50.0])) == [(0.0, 1.0), (0.5, 0.5), (1.0, 0.0)]
    assert sorted(map(tuple, surfaces[100.0])) == [(0.5, 1.0), (1.0, 0.5)]
    # a third run without a front: half of three runs is two of the two with one
    with_empty = attainment([one, other, np.zeros((0, 2))], (100.0 / 3, 50.0, 100.0))
    assert sorted(map(tuple, with_empty[50.0])) == [(0.5, 1.0), (1.0, 0.5)]
    assert len(with_empty[100.0 / 3]) == 3 and len(with_empty[100.0]) == 0


def test_objectives_by_name_their_sense_and_refusals():
    assert objective_index("energy") == "traction_energy_kwh"
    assert objective_index("j") == "j_seed004"
    assert objective_index("p95_abs_error_kmh") == "p95_abs_error_kmh"
    for signed in ("stopping_error", "running_time_error", "steps"):
        with pytest.raises(ScenarioError, match="not an objective"):
            objective_index(signed)
    with pytest.raises(ScenarioError, match="did you mean energy"):
        objective_index("enregy")
    assert objective_index("worst_arrival") == "journey_worst_arrival_s"
    assert objective_index("punctuality") == "abs_running_time_error"
    assert Requirement.parse("journey_worst_stop_m<=0.1").limit == 0.1
    with pytest.raises(ScenarioError, match="unknown index"):  # a run's report has no such
        Requirement.parse_list("journey_worst_stop_m<=0.1", "report.require")
    objectives = Objectives("itae", (Requirement("max_jerk", 0.75),),
                            ("energy", "regenerated_energy_kwh"))
    record = Evaluation(0, {}, 0.0, "ok", 0.0, {"traction_energy_kwh": 30.0,
                                                 "regenerated_energy_kwh": 12.0,
                                                 "max_jerk": 0.5})
    F, G = objectives.vector(record)
    assert list(F) == [30.0, -12.0]  # more regenerated energy is better: maximised
    assert G[0] == pytest.approx((0.5 - 0.75) / 1.0) and G[-1] < 0.0
    assert objectives.score(record.indices) == (30.0, "ok", "")
    assert objectives.score({**record.indices, "max_jerk": 0.9})[1] == "infeasible"
    failed = Evaluation(1, {}, PENALTY, "timeout", 0.0)
    F, G = objectives.vector(failed)
    assert np.all(G > 0.0) and np.all(F == PENALTY)


def synthetic(values, overrides, objective, index):
    """A candidate's indices without a run: energy falls and tracking worsens with the
    gain a; a jerk above 0.75 for b > 0.8; a candidate with a < 0.05 fails."""
    a, b = overrides["adrc.mu1"] / 10000.0, overrides["adrc.beta1"] / 3000.0
    if a < 0.05:
        return Evaluation(index, overrides, PENALTY, "diverged", 0.0)
    indices = {"traction_energy_kwh": 30.0 - 2.0 * a + b, "itae": 1.0 + 4.0 * a * a + b,
               "max_jerk": 0.5 + 0.5 * b}
    value, status, message = objective.score(indices)
    return Evaluation(index, overrides, value, status, 0.0, indices, message)


def settings(evaluations=48, **extra):
    return TuningSettings("nsga2", "seed000",
                          SearchSpace.parse(["adrc.mu1=100:10000,adrc.beta1=10:3000"]),
                          evaluations, seed=2, workers=2, options={"population_size": 8},
                          requirements=(Requirement("max_jerk", 0.75),),
                          objectives=("energy", "itae"), **extra)


def test_a_tuning_writes_its_front_hypervolume_and_chosen_member(tmp_path):
    tuner = ParetoTuner(load_scenario("seed000"), settings(), tmp_path, evaluate=synthetic,
                        progress=False)
    result = tuner.run()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["evaluations_used"] == len(result.X) == 48
    rows = list(csv.DictReader((tmp_path / "front.csv").open()))
    assert len(rows) == summary["front_size"] > 3
    log = {record["index"]: record for record in map(
        json.loads, (tmp_path / "evaluations.jsonl").read_text().splitlines())}
    for row in rows:  # each row is a feasible evaluation, re-run by its row id
        record = log[int(row["row"])]
        assert record["status"] == "ok" and record["indices"]["max_jerk"] <= 0.75
        assert float(row["itae"]) == record["indices"]["itae"]
    points = np.array([[float(row["traction_energy_kwh"]), float(row["itae"])] for row in rows])
    assert np.all(nondominated(points))
    ok = np.array([[r["indices"]["traction_energy_kwh"], r["indices"]["itae"]]
                   for r in log.values() if r["status"] == "ok"])
    assert len(points) == np.sum(nondominated(ok))  # nothing feasible it misses
    volumes = [float(row["hypervolume"]) for row in csv.DictReader(
        (tmp_path / "hypervolume.csv").open())]
    assert len(volumes) == 6 and volumes == sorted(volumes) and volumes[-1] > 0.0
    assert volumes[-1] == pytest.approx(summary["hypervolume"])
    chosen = [row for row in rows if row["chosen"] == "True"]
    assert len(chosen) == 1 and summary["chosen"]["by"] == "knee"
    best = yaml.safe_load((tmp_path / "best.yaml").read_text())
    assert best["base"] == "seed000"
    tuned = {name: value for node in best.values() if isinstance(node, dict)
             for name, value in node["ros__parameters"].items()}
    assert tuned["adrc.mu1"] == pytest.approx(float(chosen[0]["adrc.mu1"]))
    for row in rows:  # every member re-run by its row id: a scenario of its own
        member = yaml.safe_load((tmp_path / row["scenario"]).read_text())
        assert row["scenario"] == f"front/row-{int(row['row']):05d}.yaml"
        assert {name: value for node in member.values() if isinstance(node, dict)
                for name, value in node["ros__parameters"].items()}["adrc.beta1"] == \
            pytest.approx(float(row["adrc.beta1"]))
    assert len(list((tmp_path / "front").iterdir())) == len(rows)
    assert best == yaml.safe_load((tmp_path / chosen[0]["scenario"]).read_text())
    assert (tmp_path / "pareto.png").stat().st_size > 0
    assert "stop" in summary["energy_bound"]["error"]  # seed 000 runs to no stop: no bound
    pandas = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    table = pandas.read_parquet(tmp_path / "front.parquet")  # the same rows, typed
    assert list(table["row"]) == [int(row["row"]) for row in rows]
    assert list(table["itae"]) == [float(row["itae"]) for row in rows]


def test_pseudo_weights_and_reference_point_choose_as_stated(tmp_path):
    energy_first = Choice.parse("0.95,0.05", "31,3", 2)
    ParetoTuner(load_scenario("seed000"), settings(), tmp_path, energy_first,
                evaluate=synthetic, progress=False).run()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["reference_point"] == [31.0, 3.0]
    objectives = {o["index"]: o for o in summary["objectives"]}
    chosen = summary["chosen"]["objectives"]
    assert chosen["traction_energy_kwh"] == pytest.approx(
        objectives["traction_energy_kwh"]["ideal"], abs=0.1 * (
            objectives["traction_energy_kwh"]["nadir"] - objectives["traction_energy_kwh"][
                "ideal"]))
    for bad in (("1,2,3", None), ("-1,2", None), (None, "1,nan")):
        with pytest.raises(ScenarioError):
            Choice.parse(*bad, 2)


def test_a_resumed_tuning_gives_the_uninterrupted_front(tmp_path):
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    ParetoTuner(load_scenario("seed000"), settings(), whole, evaluate=synthetic,
                progress=False).run()
    cut.mkdir()
    lines = (whole / "evaluations.jsonl").read_text().splitlines(keepends=True)
    (cut / "tuning.json").write_text((whole / "tuning.json").read_text())
    (cut / "evaluations.jsonl").write_text("".join(lines[:21]) + lines[21][:30])  # cut short
    calls = []

    def counted(*args):
        calls.append(args[3])
        return synthetic(*args)

    ParetoTuner(load_scenario("seed000"), settings(), cut, resume=True, evaluate=counted,
                progress=False).run()
    assert min(calls) == 21 and len(calls) == 48 - 21
    assert (cut / "front.csv").read_text() == (whole / "front.csv").read_text()
    assert (cut / "hypervolume.csv").read_text() == (whole / "hypervolume.csv").read_text()


def test_no_feasible_candidate_means_no_front_and_no_best(tmp_path):
    strict = TuningSettings("nsga3", "seed000",
                            SearchSpace.parse(["adrc.mu1=100:10000,adrc.beta1=10:3000"]), 16,
                            seed=2, workers=1, options={"population_size": 8},
                            requirements=(Requirement("max_jerk", 0.1),),
                            objectives=("energy", "itae"))
    ParetoTuner(load_scenario("seed000"), strict, tmp_path, evaluate=synthetic,
                progress=False).run()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["front_size"] == 0 and not (tmp_path / "best.yaml").exists()
    assert math.isclose(summary["feasible_evaluations"], 0)


@pytest.mark.parametrize("arguments, message", [
    (["--objectives", "itae"], "two or more"),
    (["--objectives", "energy,stopping_error"], "not an objective"),
    (["--objectives", "energy,itae", "--fitness", "j"], "name them all"),
    (["--weights", "1,1"], "give --objectives"),
    (["--objectives", "energy,itae", "--weights", "1"], "2 finite numbers"),
    (["--objectives", "energy,itae", "--trains", "2", "--statistic", "q2"], "qP"),
    (["--trains", "0"], "at least 1"),
    (["--objectives", "energy,itae", "--trains", "2", "--statistic", "mean,worst,worst"],
     "one per objective"),
    (["--objectives", "energy,itae", "--algorithm", "pso"], "minimises one number"),
    (["--objectives", "energy,itae", "--algorithm", "pso", "--weights", "1,1", "--reference",
      "1,1"], "gives one best"),
])
def test_tune_refuses_bad_objectives_in_one_line_and_writes_nothing(tmp_path, arguments,
                                                                    message):
    out = tmp_path / "out"
    result = subprocess.run([*invocation("tune"), "--scenario", "seed004-metro-ato",
                             "--in-process", "--evaluations", "4", "--out", str(out),
                             "--require", "abs_stopping_error<=0.1",
                             *arguments], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stderr
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.slow
def test_a_candidate_over_trains_is_judged_by_its_statistic_and_its_worst_train():
    values = load_scenario("seed004-metro-ato")
    objective = Objectives("itae", (Requirement("abs_stopping_error", 0.1),),
                           ("energy", "p95_abs_error_kmh"))
    overrides = {"ladrc.omega_c": 3.0}
    each = [evaluate_in_process(apply_overrides(values, draw_train(
        RANGES, 7, number, values["odometry.enabled"])), overrides, objective, 0)
        for number in range(3)]
    energies = [record.indices["traction_energy_kwh"] for record in each]
    assert len(set(energies)) == 3  # three different trains
    for statistic, expected in (("mean", np.mean(energies)), ("worst", max(energies)),
                                ("q0.5", np.median(energies))):
        record = evaluate_over_trains(values, overrides, objective, 4,
                                      spread=TrainSpread(3, 7, statistic),
                                      evaluate=evaluate_in_process)
        assert record.index == 4 and record.indices["trains"] == 3
        assert record.indices["traction_energy_kwh"] == pytest.approx(expected, rel=1e-12)
    assert record.indices["abs_stopping_error"] == max(
        r.indices["abs_stopping_error"] for r in each)  # the requirement's worst train
    p95 = [record.indices["p95_abs_error_kmh"] for record in each]
    both = evaluate_over_trains(values, overrides, objective, 4,
                                spread=TrainSpread(3, 7, "mean,worst"),
                                evaluate=evaluate_in_process)  # one per objective
    assert both.indices["traction_energy_kwh"] == pytest.approx(np.mean(energies), rel=1e-12)
    assert both.indices["p95_abs_error_kmh"] == max(p95)
    strict = Objectives("itae", (Requirement("abs_stopping_error", min(
        r.indices["abs_stopping_error"] for r in each) * 1.0001),), ("energy", "itae"))
    # met by the best train, broken by the others: infeasible
    broken = evaluate_over_trains(values, overrides, strict, 0, spread=TrainSpread(3, 7),
                                  evaluate=evaluate_in_process)
    assert broken.status == "infeasible"
    other = evaluate_over_trains(values, overrides, objective, 0, spread=TrainSpread(3, 8),
                                 evaluate=evaluate_in_process)
    assert other.indices["traction_energy_kwh"] != pytest.approx(np.mean(energies), rel=1e-9)


@pytest.mark.slow
def test_a_journey_candidate_is_judged_by_its_worst_station():
    values = load_scenario("seed004-metro-line")
    objective = Objectives("itae", (Requirement("journey_worst_stop_m", 0.1),),
                           ("energy", "worst_arrival"))
    record = evaluate_in_process(values, {"ladrc.omega_c": 3.0}, objective, 0)
    from ato_nodes.results.journeys import score_with_journey
    journey = score_with_journey(apply_overrides(values, {"ladrc.omega_c": 3.0}))
    stations = journey["journey"]["stations"][1:]
    assert record.indices["journey_worst_stop_m"] == max(abs(s["stop_error"]) for s in stations)
    assert record.indices["journey_worst_arrival_s"] == max(abs(s["arrival_lateness"])
                                                            for s in stations)
    assert "journey" not in record.indices  # the log keeps a line a candidate
    F, G = objective.vector(record)
    assert list(F) == [record.indices["traction_energy_kwh"],
                       record.indices["journey_worst_arrival_s"]]
    assert G[0] == pytest.approx(record.indices["journey_worst_stop_m"] - 0.1)


FRONT_TUNING = ["--scenario", "seed000", "--set", "run.duration=150", "--params",
                "adrc.mu1=600:60000,adrc.mu2=550:55000", "--objectives", "energy,itae",
                "--evaluations", "12", "--population", "4", "--quiet"]


def tune_front(out, *extra):
    result = subprocess.run([*invocation("tune"), *FRONT_TUNING, "--out", str(out), *extra],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    return list(csv.DictReader((out / "front.csv").open()))


@pytest.mark.integration
def test_a_front_is_the_same_on_dask_and_through_the_stack(tmp_path):
    pytest.importorskip("distributed")
    local = tune_front(tmp_path / "local", "--in-process", "--workers", "2")
    cluster = tune_front(tmp_path / "cluster", "--in-process", "--cluster", "local:2")
    assert (tmp_path / "local" / "front.csv").read_text() == \
        (tmp_path / "cluster" / "front.csv").read_text()
    assert (tmp_path / "local" / "hypervolume.csv").read_text() == \
        (tmp_path / "cluster" / "hypervolume.csv").read_text()
    assert len(local) == len(cluster) > 1
    stack = tune_front(tmp_path / "stack", "--workers", "2")
    # the same candidates and front; a bag's ITAE differs in the last digits (its t is
    # nanosecond stamps)
    assert [(row["row"], row["adrc.mu1"], row["adrc.mu2"], row["chosen"]) for row in stack] == \
        [(row["row"], row["adrc.mu1"], row["adrc.mu2"], row["chosen"]) for row in local]
    for ours, theirs in zip(stack, local, strict=True):
        assert float(ours["itae"]) == pytest.approx(float(theirs["itae"]), rel=1e-9)
        assert float(ours["traction_energy_kwh"]) == pytest.approx(
            float(theirs["traction_energy_kwh"]), rel=1e-9)


@pytest.mark.slow
def test_the_least_energy_bounds_every_run_of_the_nominal_train():
    from ato_nodes.core.run.scoring import score_series
    from ato_nodes.core.run.loop import simulate
    from ato_nodes.studies.energy_optimum import least_energy_of_run
    values = load_scenario("seed004-metro-ato")
    bound, running_time = least_energy_of_run(values)
    assert running_time == 165.0
    for overrides in ({}, {"ladrc.omega_c": 3.0}, {"profile.ato.acceleration": 1.0}):
        run = apply_overrides(values, overrides)
        indices = score_series(simulate(run), run)
        assert indices["running_time_error"] < 1.0  # on time: the bound's time or less
        assert bound < indices["traction_energy_kwh"]
    assert bound > 0.5 * indices["traction_energy_kwh"]  # a bound, not zero
    with pytest.raises(ScenarioError, match="stop"):
        least_energy_of_run(load_scenario("seed000"))


@pytest.mark.slow
def test_a_requirement_broken_for_good_prunes_the_run_with_a_lower_bound(tmp_path):
    values = load_scenario("seed004-metro-ato")
    space = SearchSpace.parse(["ladrc.omega_o=1:40,ladrc.omega_c=1:10"], values)
    requirements = (Requirement("max_abs_error_kmh", 0.5), Requirement("abs_stopping_error", 0.1))

    def tuning(out, prune):
        settings = TuningSettings("nsga2", "seed004-metro-ato", space, 20, seed=1, workers=2,
                                  in_process=True, options={"population_size": 20},
                                  requirements=requirements, prune=prune,
                                  objectives=("energy", "p95_abs_error_kmh"))
        ParetoTuner(values, settings, tmp_path / out, progress=False).run()
        return sorted((json.loads(line) for line in (tmp_path / out / "evaluations.jsonl")
                       .read_text().splitlines()), key=lambda record: record["index"])

    pruned, whole = tuning("pruned", True), tuning("whole", False)
    broken = [r["index"] for r in whole if r["indices"]["max_abs_error_kmh"] > 0.5]
    assert broken and len(broken) < 20
    assert [r["index"] for r in pruned if r["status"] == "pruned"] == broken
    for ours, theirs in zip(pruned, whole, strict=True):
        if ours["status"] == "pruned":  # ended early: a lower bound of the whole run's
            assert 0.5 < ours["fitness"] * 3.6 <= theirs["indices"]["max_abs_error_kmh"]
            F, G = Objectives("itae", requirements, ("energy", "p95_abs_error_kmh"),
                              True).vector(Evaluation(**{**ours, "conditions": ""}))
            assert 0.0 < G[0] <= (theirs["indices"]["max_abs_error_kmh"] - 0.5) / 1.0
            assert list(G[1:]) == [0.0, 0.0] and np.all(F == PENALTY)
        else:
            assert ours["indices"] == theirs["indices"]


def test_a_weighted_sum_is_one_fitness_with_requirements_first():
    from ato_nodes.studies.tuning import INFEASIBLE, WeightedSum
    summed = WeightedSum("itae", (Requirement("max_jerk", 0.75),),
                         ("energy", "regenerated_energy_kwh"), weights=(2.0, 0.5))
    indices = {"traction_energy_kwh": 30.0, "regenerated_energy_kwh": 12.0, "max_jerk": 0.5}
    assert summed.score(indices) == (2.0 * 30.0 - 0.5 * 12.0, "ok", "")
    value, status, _ = summed.score({**indices, "max_jerk": 0.9})
    assert status == "infeasible" and value > INFEASIBLE
    assert summed.pruned_by(1.0) is None


@pytest.mark.slow
def test_compare_tuners_judges_every_run_by_the_same_reference_point(tmp_path):
    result = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "compare_tuners.py"), "--algorithms", "nsga2",
         "pso", "--seeds", "1", "--evaluations", "16", "--population", "8", "--scenario",
         "seed004-metro-ato", "--params", "ladrc.omega_o=1:40,ladrc.omega_c=1:10",
         "--objectives", "energy,p95_abs_error_kmh", "--reference", "30,0.5", "--require",
         "abs_stopping_error<=0.1", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr
    table = (tmp_path / "comparison.md").read_text()
    assert "| nsga2 | 1 | 16 |" in table and "| pso | 1 | 16 |" in table
    summary = json.loads((tmp_path / "nsga2-seed1" / "summary.json").read_text())
    assert summary["reference_point"] == [30.0, 0.5]
    assert f"nsga2 seed 1: hypervolume {summary['hypervolume']:.6g}," in result.stdout
    # one seed: its median attainment surface is its front, of the same hypervolume
    assert table.split("| nsga2 |")[1].split("\n")[0].rstrip(" |").endswith(
        f"{summary['hypervolume']:.6g}")
    with (tmp_path / "attainment.csv").open() as handle:
        surfaces = list(csv.DictReader(handle))
    assert {row["algorithm"] for row in surfaces} == {"nsga2", "pso"}
    assert (tmp_path / "attainment.png").stat().st_size > 0
    baseline = json.loads((tmp_path / "pso-seed1" / "summary.json").read_text())
    assert baseline["weights"] == pytest.approx([1 / 30, 1 / 0.5])
