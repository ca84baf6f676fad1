"""The report's verdict, identity and interactive page, from runs made in-process (no
browser needed: tests/test_report_render.py renders the page)."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.analysis import FAIL, PASS, UNMEASURED, judge, verdict_rows, write_report
from ato_nodes.bagio import Run
from ato_nodes.core.errors import ScenarioError
from ato_nodes.core.loop import simulate
from ato_nodes.core.scenario import apply_overrides, load_scenario, scenario_names
from ato_nodes.core.operation import drive_modes, windowed_jerk
from ato_nodes.report_html import mode_segments


def make_run(tmp_path: Path, name: str, overrides=()) -> Run:
    values = apply_overrides(load_scenario("seed004-metro"), list(overrides))  # 0.4 s
    path = tmp_path / name
    path.mkdir()
    (path / "summary.json").write_text(json.dumps({"scenario": "seed004-metro"}))
    return Run(path, simulate(values), values, {})


@pytest.fixture(scope="module")
def metro(tmp_path_factory):
    return make_run(tmp_path_factory.mktemp("runs"), "metro")


def with_requirements(run: Run, text: str, bands: str = "") -> Run:
    return Run(run.path, run.series, {**run.parameters, "report.require": text,
                                      "report.error_bands": bands}, {})


def test_each_requirement_passes_or_fails_by_its_limit(metro):
    indices = judge(metro).indices
    error, switches = indices["max_abs_error_kmh"], indices["switch_count"]
    report = judge(with_requirements(
        metro, f"max_abs_error_kmh<={error + 0.01}, switch_count<={switches - 1}, "
               f"overshoot_percent<=1"))
    assert report.status("max_abs_error_kmh") == PASS
    assert report.status("switch_count") == FAIL
    assert report.status("overshoot_percent") == UNMEASURED  # not a step target
    assert report.status("itae") == ""
    overall, text = report.summary
    assert overall == FAIL and "1 of 3 requirements met" in text and "switches" in text
    exactly = judge(with_requirements(metro, f"switch_count<={switches}"))
    assert exactly.summary[0] == PASS  # the limit itself is met


def test_the_verdict_puts_required_indices_first_one_column_per_run(metro, tmp_path):
    other = make_run(tmp_path, "tuned", ["dadrc.b1=60"])
    reports = [judge(with_requirements(metro, "max_jerk<=0.75, max_abs_error_kmh<=1")),
               judge(with_requirements(other, "max_jerk<=0.5"))]
    rows = verdict_rows(reports)
    assert [row.key for row in rows[:2]] == ["max_jerk", "max_abs_error_kmh"]
    assert all(len(row.cells) == 2 for row in rows)
    assert rows[0].requirement == "per run" and "(<= 0.5)" in rows[0].cells[1][0]
    assert rows[1].requirement == "<= 1" and rows[1].cells[1][1] == ""
    assert {row.key for row in rows} >= {"itae", "net_energy_kwh", "stopping_error"}


def test_the_run_is_named_with_its_scenario_train_controller_gains_and_line(metro):
    identity = judge(metro).identity
    assert identity["scenario"] == "seed004-metro"
    assert identity["train"].startswith("metro-b")
    assert identity["controller"].startswith("discrete_adrc")
    assert f"b1 {metro.parameters['dadrc.b1']:g}" in identity["gains"]
    assert "2.6 km" in identity["line"]


def test_the_page_is_self_contained_with_its_figures_and_verdict(metro, tmp_path):
    run = with_requirements(metro, "max_abs_error_kmh<=100, switch_count<=0", bands="0.3")
    markdown, page = write_report([run], [], tmp_path / "report")
    text = page.read_text()
    assert not re.search(r"<script[^>]*\bsrc=", text)  # plotly.js is inline, no CDN
    assert text.count("* plotly.js v") == 1  # its banner: embedded once
    assert len(re.findall(r'class="plotly-graph-div"', text)) == 2  # time, distance
    assert "data-plots-rendered" in text and "\\u00b10.3 band" in text  # JSON-escaped ±
    assert re.search(r"<td[^>]*>max abs\(e\) km/h</td><td[^>]*>&lt;= 100</td>"
                     r"<td style='background:#d8f3dc'>[0-9.]+ pass</td>", text)
    assert re.search(r"<td style='background:#ffccd5'>\d+ fail</td>", text)
    assert "**FAIL** metro: 1 of 2 requirements met" in markdown.read_text()
    assert not (tmp_path / "report" / "convergence.png").exists()


def test_two_runs_get_difference_plots(metro, tmp_path):
    other = make_run(tmp_path, "tuned", ["dadrc.b1=60"])
    _, page = write_report([metro, other], [], tmp_path / "report")
    text = page.read_text()
    assert "speed difference to metro" in text and "command difference to metro" in text


def test_the_mode_timeline_and_jerk_plot_show_what_the_indices_count(metro):
    indices = judge(metro).indices
    t, force = metro.series["t"], metro.series["force"]
    modes = drive_modes(force)
    traction = mode_segments(t, modes, 1)
    braking = mode_segments(t, modes, -1)
    starts = sorted([(x, 1) for x in traction[::3]] + [(x, -1) for x in braking[::3]])
    changes = sum(a[1] != b[1] for a, b in zip(starts, starts[1:]))
    assert changes == indices["switch_count"] > 0
    _, jerk = windowed_jerk(t, metro.series["acceleration"])
    assert np.max(np.abs(jerk)) == pytest.approx(indices["max_jerk"])


def test_bad_report_parameters_are_one_line(metro):
    with pytest.raises(ScenarioError, match=r"^--set: report.require must be INDEX<=VALUE"):
        apply_overrides(metro.parameters, ["report.require=max_abs_error_kmh<1"])
    with pytest.raises(ScenarioError, match=r"report.error_bands must be numbers of km/h"):
        apply_overrides(metro.parameters, ["report.error_bands=wide"])
    with pytest.raises(ScenarioError, match=r"metro: report.require: .*did you mean "
                                            r"max_abs_error_kmh"):  # a bag is anyone's file
        judge(with_requirements(metro, "max_abs_eror_kmh<=1"))
    # a scenario's is refused before anything starts
    with pytest.raises(ScenarioError, match=r"^parameters: report.require: unknown index "
                                            r"'swich_count' \(did you mean switch_count\?\)$"):
        apply_overrides(load_scenario("seed004-metro"), ["report.require=swich_count<=3"])


def test_every_shipped_scenario_names_indices_the_scorer_gives():
    for name in scenario_names():
        parameters = load_scenario(name)
        judge(Run(Path(name), {"t": np.zeros(2), "target": np.zeros(2),
                               "speed": np.zeros(2)}, parameters, {}))  # raises if misnamed
