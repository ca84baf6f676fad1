"""Every machine-readable output is strict JSON: a value not measured (a run that never
arrives has no arrival time) is null, never the bare NaN / Infinity that
JSON.parse and other strict readers refuse."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ato_nodes.reports.report import write_report
from ato_nodes.bags.bagio import read_run
from ato_nodes.cli import score_bag
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from bagfile import write_run_bag
from commands import invocation

ROOT = Path(__file__).resolve().parents[1]
NOT_MEASURED = ("arrival_time", "running_time_error")  # the train is still moving at 30 s


def refuse(constant: str):
    raise ValueError(f"bare {constant} in JSON")


def strict(text: str):
    return json.loads(text, parse_constant=refuse)


def script(name: str, *args, timeout=300):
    return subprocess.run([*invocation(name), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)


@pytest.fixture(scope="module")
def metro_start(tmp_path_factory) -> Path:
    """The first 30 s of the metro run, as its bag: it ends 2.4 km before its stop."""
    values = apply_overrides(load_scenario("seed004-metro"), ["run.duration=30"])
    return write_run_bag(tmp_path_factory.mktemp("bags") / "metro-start", simulate(values),
                         values, status="completed")


def test_the_strict_reader_refuses_what_pythons_json_writes_by_default():
    with pytest.raises(ValueError, match="bare NaN"):
        strict(json.dumps({"arrival_time": float("nan")}))


def test_score_bag_json_of_a_run_without_arrival_is_strict(metro_start, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["score_bag", str(metro_start), "--json"])
    score_bag.main()
    indices = strict(capsys.readouterr().out)
    assert all(indices[name] is None for name in NOT_MEASURED)
    assert indices["abs_stopping_error"] > 2000 and indices["steps"] == 300


@pytest.mark.slow
def test_the_reports_indices_json_of_a_run_without_arrival_is_strict(metro_start, tmp_path):
    write_report([read_run(metro_start)], [], tmp_path / "report")
    indices = strict((tmp_path / "report" / "indices.json").read_text())["metro-start"]
    assert all(indices[name] is None for name in NOT_MEASURED)


@pytest.mark.slow
def test_a_tunings_summary_is_strict(tmp_path):
    out = tmp_path / "tune"
    result = script("tune.py", "--algorithm", "pso", "--scenario", "seed004-metro", "--params",
                    "dadrc.b1=20:80", "--evaluations", "4", "--population", "2", "--in-process",
                    "--set", "run.duration=30", "--quiet", "--out", out)
    assert result.returncode == 0, result.stderr
    summary = strict((out / "summary.json").read_text())
    assert all(summary["best_indices"][name] is None for name in NOT_MEASURED)
    strict((out / "tuning.json").read_text())


@pytest.mark.slow
def test_the_robustness_report_is_strict(tmp_path):
    result = script("robustness.py", "seed004-metro", "--samples", "2", "--workers", "1",
                    "--set", "run.duration=20", "--out", tmp_path / "r")
    assert result.returncode == 0, result.stderr
    assert len(strict((tmp_path / "r" / "robustness.json").read_text())["samples"]) == 2


@pytest.mark.integration
def test_a_stack_run_without_arrival_writes_strict_json_everywhere(tmp_path):
    """The 30 s metro run through the nodes: its summary.json, score_bag --json and the
    report's indices.json."""
    bag = tmp_path / "metro-start"
    result = script("run_stack.py", "--scenario", "seed004-metro", "--duration", "30",
                    "--out", bag, "--quiet")
    assert result.returncode == 0, result.stderr
    summary = strict((bag / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert all(summary["indices"][name] is None for name in NOT_MEASURED)
    scored = script("score_bag.py", bag, "--json")
    assert scored.returncode == 0, scored.stderr
    assert strict(scored.stdout) == summary["indices"]
    report = script("analyze.py", bag, "--out", tmp_path / "report")
    assert report.returncode == 0, report.stderr
    indices = strict((tmp_path / "report" / "indices.json").read_text())["metro-start"]
    assert {k: v for k, v in indices.items() if k != "skipped"} == summary["indices"]
