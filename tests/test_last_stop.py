"""A journey's run ended at its last stop (run.last_stop_hold, core/run/last_stop.py): the
hold counted from the first standing sample, the same end step in the Python loop, the
compiled loop (in chunks too) and through the stack, the cap run.duration for a train that
does not get there, the bag and the tuner taking the run as complete, bad values in one
line."""

import json
import subprocess

import numpy as np
import pytest

from ato_nodes.bags.bagio import Run, read_run, resimulate
from ato_nodes.core.base import kernels
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, prepare
from ato_nodes.core.config.schema import steps
from ato_nodes.core.run import fast_loop
from ato_nodes.core.run.last_stop import (AT_LAST_STOP, NEVER, LastStop, held, last_stop,
                                          planned_steps, standing)
from ato_nodes.core.run.loop import simulate
from ato_nodes.results.journeys import run_journey, run_timetable
from ato_nodes.studies.tuning import evaluate_in_process
from commands import ROOT, invocation, run_stack

SCENARIO = "seed004-metro-line"  # its run.last_stop_hold: 10 s


def two_stops(tmp_path) -> str:
    """The metro journey's first section alone: Westgate to Market, on its timetable."""
    path = tmp_path / "two-stops.yaml"
    path.write_text("line: lines/metro-line.yaml\ntrain: metro-b\nstops:\n"
                    "  - {station: Westgate (synthetic), departure: 0}\n"
                    "  - {station: Market (synthetic), arrival: 128}\n")
    return str(path)


def short_journey(tmp_path, duration=300.0):
    return prepare(SCENARIO, [f"profile.journey.timetable={two_stops(tmp_path)}",
                              f"run.duration={duration}"])


def at_last_stop(series, values) -> np.ndarray:
    """Each sample's train standing at its last stop, as the plant counts it."""
    return (np.abs(series["speed"]) <= 0.01) & (series["position"]
                                                >= values["run.last_stop_position"])


def test_standing_counts_the_samples_at_the_last_stop_and_the_hold_ends_the_run():
    rule = LastStop(100.0, 3)
    samples = [(90.0, 5.0, 0), (99.5, 0.0, 0),  # moving, then standing short of it
               (100.0, 0.0, 1), (100.0, 0.02, 0),  # there, then moving again
               (100.2, -0.005, 1), (100.2, 0.0, 2), (100.2, 0.0, 3), (100.2, 0.0, 4)]
    stood = 0
    for position, speed, expected in samples:
        stood = standing(rule, stood, position, speed)
        assert stood == expected, (position, speed)
        assert held(rule, stood) == (expected > 3)
    assert standing(rule, 2, 100.2, -0.02) == 0  # rolling back is moving
    assert standing(NEVER, 5, 1e9, 0.0) == 0 and not held(NEVER, 10**9)
    values = {"run.last_stop_hold": 0.3, "run.last_stop_position": 100.0, "run.period": 0.1,
              "run.duration": 10.0}
    assert last_stop(values) == rule  # 0.3 s of 0.1 s periods: 3 steps
    position, speed, _ = (np.array(column) for column in zip(*samples, strict=True))
    assert planned_steps(values, position, speed) == 8  # the run ends after its last sample
    assert planned_steps(values, position[:7], speed[:7]) == 100  # not yet: run.duration's
    assert planned_steps({**values, "run.last_stop_hold": 0.0}, position, speed) == 100
    assert planned_steps({"run.period": 0.1, "run.duration": 10.0}, position, speed) == 100
    assert last_stop({**values, "run.last_stop_hold": 0.26}).hold == 3  # whole periods


@pytest.mark.slow
def test_the_run_ends_its_hold_after_the_train_stands_at_the_last_stop_as_the_scorer_sees(
        tmp_path):
    values = short_journey(tmp_path)
    period, hold = values["run.period"], values["run.last_stop_hold"]
    market = run_timetable(values).stops[-1]
    assert values["run.last_stop_position"] == market.position - values["profile.journey.berth"]
    python = simulate(values, compiled=False)
    t, standing_there = python["t"], at_last_stop(python, values)
    first = int(np.flatnonzero(~standing_there)[-1]) + 1  # the final standstill's first sample
    assert standing_there[first:].all() and len(t) - 1 - first == round(hold / period) == 100
    assert t[-1] - t[first] == pytest.approx(hold, abs=1e-9)
    assert len(t) == planned_steps(values, python["position"], python["speed"]) < steps(values)
    (origin, stop) = run_journey(python, values, run_timetable(values)).stations
    assert stop.outcome == "stopped" and stop.verdict == "pass" and stop.arrival == t[first]
    # the run until its end is the run without it
    unended = simulate(apply_overrides(values, {"run.last_stop_hold": 0.0}), compiled=False)
    assert len(unended["t"]) == steps(values)
    for name in python:
        assert np.array_equal(python[name], unended[name][:len(t)], equal_nan=True), name


@pytest.mark.slow
@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")
def test_the_compiled_loop_ends_at_the_python_loops_step_with_its_bits_in_chunks_too(
        tmp_path, monkeypatch):
    values = short_journey(tmp_path)
    python, compiled = simulate(values, compiled=False), simulate(values)
    with monkeypatch.context() as patch:  # one step a call: the count goes chunk to chunk
        patch.setattr(fast_loop, "FIRST_CHUNK", 1)
        patch.setattr(fast_loop, "CHUNK_SECONDS", 0.0)
        chunked = simulate(values)
    assert len(python["t"]) == len(compiled["t"]) == len(chunked["t"]) < steps(values)
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name
        assert np.array_equal(chunked[name], python[name], equal_nan=True), name


def test_a_train_that_does_not_reach_its_last_stop_ends_at_run_duration(tmp_path):
    values = short_journey(tmp_path, duration=100.0)  # Market at 125.5 s
    for compiled in (True, False):
        assert len(simulate(values, compiled=compiled)["t"]) == steps(values) == 1000


def test_a_bag_counts_its_planned_steps_from_its_states(tmp_path):
    values = short_journey(tmp_path)
    series = simulate(values)
    ended = Run(tmp_path, series, values, {})
    assert ended.planned_steps == ended.recorded_steps == len(series["t"]) < steps(values)
    assert ended.ended_at_last_stop and ended.partial is None
    cut = Run(tmp_path, {name: column[:500] for name, column in series.items()}, values, {})
    assert cut.planned_steps == steps(values) and not cut.ended_at_last_stop
    assert cut.partial == f"interrupted at step 500 of {steps(values)}"
    anyones = Run(tmp_path, series, None, {})  # someone else's bag: nothing planned
    assert anyones.planned_steps is None and not anyones.ended_at_last_stop
    assert anyones.partial is None


def test_the_tuner_takes_a_run_ended_at_its_last_stop_as_complete(tmp_path):
    evaluation = evaluate_in_process(short_journey(tmp_path), {}, "itae", 0)
    assert evaluation.status == "ok" and evaluation.indices["steps"] < 3000


def test_a_run_without_the_hold_is_the_one_before_it():
    values = load_scenario("seed004-metro")
    assert values["run.last_stop_hold"] == 0.0 and last_stop(values) == NEVER


@pytest.mark.parametrize("scenario, overrides, message", [
    ("seed004-metro", ["run.last_stop_hold=5"],
     "run.last_stop_hold ends a journey's run at its last stop; profile.kind ato has no stops"),
    (SCENARIO, ["run.last_stop_hold=-1"], "run.last_stop_hold = -1.0 is out of range"),
    (SCENARIO, ["run.last_stop_hold=soon"], "run.last_stop_hold must be a number"),
    (SCENARIO, ["run.last_stop_position=11000"],
     "run.last_stop_position is the timetable's last mark less profile.journey.berth when "
     "run.last_stop_hold is above 0: give one of them"),
])
def test_bad_values_are_one_line(scenario, overrides, message):
    with pytest.raises(ScenarioError, match=message) as error:
        prepare(scenario, overrides)
    assert "\n" not in str(error.value)


def test_a_scenario_file_giving_the_derived_position_is_refused_in_one_line(tmp_path):
    text = (ROOT / "msg_config" / "scenarios" / f"{SCENARIO}.yaml").read_text()
    scenario = tmp_path / "given.yaml"
    scenario.write_text(text.replace("    run.last_stop_hold: 10.0\n", "    run.last_stop_hold: "
                                     "10.0\n    run.last_stop_position: 11000.0\n"))
    with pytest.raises(ScenarioError, match="run.last_stop_position is the timetable's"):
        load_scenario(str(scenario))
    done = subprocess.run([*invocation("run_stack"), "--scenario", "seed004-metro", "--out",
                           str(tmp_path / "bag"), "--set=run.last_stop_hold=5"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 2 and not (tmp_path / "bag").exists()
    assert done.stderr.count("\n") == 1 and "profile.kind ato has no stops" in done.stderr


@pytest.mark.integration
def test_the_stack_ends_at_the_in_process_step_with_its_bits_and_a_complete_bag(tmp_path):
    overrides = [f"profile.journey.timetable={two_stops(tmp_path)}", "run.duration=300"]
    bag = tmp_path / "bag"
    run_stack(SCENARIO, bag, overrides)
    values = prepare(SCENARIO, overrides)
    series = simulate(values)
    summary = json.loads((bag / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["ended"] == AT_LAST_STOP
    assert summary["steps"] == summary["recorded_steps"] == len(series["t"]) < steps(values)
    run = read_run(bag)
    for name in series:
        if name != "t":
            assert np.array_equal(run.series[name], series[name], equal_nan=True), name
    assert run.partial is None and run.ended_at_last_stop
    assert run.planned_steps == run.recorded_steps == len(series["t"])
    assert resimulate(run)[1] == []  # the bag's values run the same run again
    scored = subprocess.run([*invocation("score_bag"), str(bag)], capture_output=True,
                            text=True, timeout=120, cwd=ROOT)
    assert scored.returncode == 0, scored.stderr
    assert f"complete: ended {AT_LAST_STOP} after {len(series['t'])} steps" in scored.stdout
    assert "partial" not in scored.stdout
