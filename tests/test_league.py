"""The league of controller kinds (scripts/league.py, studies/league.py): every kind on
the same scenario, tuned alike or with its gains, over the same real trains; a kind that
cannot run says why in its row; bad input is refused in one line."""

import csv
import dataclasses
import json
import os
import signal
import subprocess

import pytest

from ato_nodes.core.config.components import CONTROLLERS
from ato_nodes.core.config.schema import SPEC_BY_NAME
from ato_nodes.studies.league import (LeagueSettings, check_kinds, markdown, prepare_entries,
                                      registered_kinds, table)
from ato_nodes.studies.robustness import FACTORS, SEEDS
from commands import ROOT, invocation, one_line_exit_2, script
from progress_lines import read_progress_until

SCENARIO = "seed004-metro-ato"


def test_the_default_kinds_are_the_registrys_a_plugins_included(monkeypatch):
    plugin = dataclasses.replace(CONTROLLERS["pid"], kind="plugin_pid")
    monkeypatch.setitem(CONTROLLERS.components, "plugin_pid", plugin)
    assert registered_kinds() == tuple(CONTROLLERS.components)
    assert "plugin_pid" in registered_kinds()
    check_kinds(["plugin_pid", "pid"])  # a registered kind is a --kinds name


def test_a_tuned_kind_starts_at_its_shipped_gains_and_an_untuned_one_keeps_the_scenarios():
    """The scenario's own kind would otherwise start its tuning at gains tuned on it."""
    kinds = ("linear_adrc", "pid")
    _, (ours, pid) = prepare_entries(LeagueSettings(SCENARIO, kinds))
    _, (tuned, _) = prepare_entries(LeagueSettings(SCENARIO, kinds, tune=10))
    assert (ours.label, pid.label, tuned.label) == (
        "linear_adrc (scenario's gains)", "pid (shipped gains)", "linear_adrc (tuned 10)")
    for name, _, _ in CONTROLLERS["linear_adrc"].search_space:
        assert tuned.values[name] == SPEC_BY_NAME[name].default
    assert ours.values["ladrc.omega_o"] != SPEC_BY_NAME["ladrc.omega_o"].default
    assert pid.values["controller.kind"] == "pid"


def test_a_gain_given_goes_to_its_kind_alone():
    _, (pid, ladrc) = prepare_entries(LeagueSettings(
        SCENARIO, ("pid", "linear_adrc"), sets=("pid.kp=123", "run.duration=50")))
    assert pid.label == "pid (shipped gains; pid.kp=123)" and pid.values["pid.kp"] == 123
    assert ladrc.values["pid.kp"] == SPEC_BY_NAME["pid.kp"].default
    assert pid.values["run.duration"] == ladrc.values["run.duration"] == 50


def test_a_kind_the_scenario_refuses_gets_a_row_saying_why_in_one_line():
    _, (gpc,) = prepare_entries(LeagueSettings(SCENARIO, ("gpc",)))
    assert gpc.values is None and "controller.preview" in gpc.reason
    rows = table([gpc], {})
    lines = markdown(rows).splitlines()
    assert lines[-1].startswith(f"| gpc (shipped gains) | cannot run: {gpc.reason}")
    assert "\n" not in gpc.reason


@pytest.mark.parametrize("arguments, words", [
    (["--kinds", "pid", "no_such_kind"], ["no_such_kind", "known"]),
    (["--kinds", "pid", "pid"], ["pid more than once"]),
    (["--trains", "0"], ["--trains"]),
    (["--tune", "-1"], ["--tune"]),
    (["--kinds", "pid", "--set", "ladrc.omega_o=3"], ["ladrc.omega_o", "--kinds"]),
    (["--set", "controller.kind=pid"], ["--kinds"]),
    (["--require", "max_abs_error_kph<=1"], ["unknown index"]),
    (["--cluster", "nowhere"], ["--cluster"]),
])
def test_bad_input_is_refused_in_one_line_and_nothing_is_written(tmp_path, arguments, words):
    out = tmp_path / "league"
    one_line_exit_2(script("league.py", SCENARIO, *arguments, "--out", out), *words)
    assert not out.exists()


def test_a_directory_or_file_that_holds_something_else_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    for out in (tmp_path, tmp_path / "notes.txt"):
        one_line_exit_2(script("league.py", SCENARIO, "--out", out), "other than a league")
    assert [path.name for path in tmp_path.iterdir()] == ["notes.txt"]
    assert (tmp_path / "notes.txt").read_text() == "mine"


def draws(path) -> list[dict]:
    """Each train's draw, in sample order (the rows are in the order they finished)."""
    with path.open() as handle:
        rows = [{name: row[name] for name in ("sample", *FACTORS, *SEEDS)}
                for row in csv.DictReader(handle)]
    return sorted(rows, key=lambda row: int(row["sample"]))


@pytest.mark.slow
def test_a_league_tunes_each_kind_alike_and_runs_them_over_the_same_trains(tmp_path):
    out = tmp_path / "league"
    command = [SCENARIO, "--kinds", "pid", "linear_adrc", "gpc", "--tune", "4", "--trains",
               "3", "--set", "run.duration=20", "--workers", "2", "--out", out]
    first = script("league.py", *command, timeout=900)
    assert first.returncode == 0, first.stderr
    report = json.loads((out / "league.json").read_text())
    pid, ladrc, gpc = report["rows"]
    assert [pid["label"], ladrc["label"]] == ["pid (tuned 4)", "linear_adrc (tuned 4)"]
    assert "controller.preview" in gpc["cannot_run"] and "summary" not in gpc
    assert pid["trains"] == ladrc["trains"] == 3
    for kind in ("pid", "linear_adrc"):  # tuned as tune.py tunes: the same budget and seed
        tuning = json.loads((out / f"tune-{kind}" / "summary.json").read_text())
        assert tuning["evaluations_used"] == 4 and tuning["seed"] == 1
        assert set(tuning["params"]) == {name for name, _, _ in CONTROLLERS[kind].search_space}
    assert draws(out / "trains-pid" / "samples.csv") == draws(
        out / "trains-linear_adrc" / "samples.csv")
    assert len(draws(out / "trains-pid" / "samples.csv")) == 3
    assert (out / "league.png").stat().st_size > 0
    assert "| pid (tuned 4) |" in first.stdout and "| gpc (tuned 4) | cannot run:" in first.stdout
    again = script("league.py", *command, timeout=900)  # continued: nothing left to run
    assert again.returncode == 0, again.stderr
    assert json.loads((out / "league.json").read_text()) == report
    other = script("league.py", *command[:-2], "--seed", "2", "--out", out)
    one_line_exit_2(other, "other settings")


def trains_done(out) -> int:
    path = out / "trains-pid" / "samples.csv"
    return len(path.read_text().splitlines()) - 1 if path.exists() else 0


@pytest.mark.slow
def test_an_interrupted_league_keeps_its_runs_and_the_same_command_ends_it_as_one_run(
        tmp_path):
    command = [SCENARIO, "--kinds", "pid", "linear_adrc", "--tune", "6", "--trains", "300",
               "--set", "run.duration=40", "--workers", "2", "--out"]
    whole = script("league.py", *command, tmp_path / "whole", timeout=900)
    assert whole.returncode == 0, whole.stderr
    out = tmp_path / "stopped"
    process = subprocess.Popen([*invocation("league.py"), *command, str(out)], cwd=ROOT,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    lines = read_progress_until(process, lambda: trains_done(out) >= 30, 600)
    os.killpg(process.pid, signal.SIGINT)  # a terminal's Ctrl-C: its workers get it too
    _, rest = process.communicate(timeout=120)
    assert process.returncode == 130, "".join(lines) + rest
    assert [line for line in rest.splitlines() if not line.startswith("trains ")] == [
        f"interrupted; every finished evaluation and train is in {out}; the same command "
        "continues"]
    assert trains_done(out) >= 30 and not (out / "league.json").exists()
    again = script("league.py", *command, out, timeout=900)
    assert again.returncode == 0, again.stderr
    assert (out / "league.json").read_text() == (tmp_path / "whole" / "league.json").read_text()


@pytest.mark.slow
def test_a_league_on_a_dask_cluster_gives_the_league_run_here(tmp_path):
    command = [SCENARIO, "--kinds", "pid", "linear_adrc", "--tune", "4", "--trains", "3",
               "--set", "run.duration=20"]
    here = script("league.py", *command, "--out", tmp_path / "here", timeout=900)
    assert here.returncode == 0, here.stderr
    cluster = script("league.py", *command, "--cluster", "local:2", "--out",
                     tmp_path / "cluster", timeout=900)
    assert cluster.returncode == 0, cluster.stderr
    assert (tmp_path / "cluster" / "league.json").read_text() == (
        tmp_path / "here" / "league.json").read_text()
