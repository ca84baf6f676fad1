"""The report's verdict, identity and interactive page, from runs made in-process (no
browser needed: tests/test_report_render.py renders the page)."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.reports.analysis import (FAIL, INDEX_COLUMNS, LIMIT_COLOUR, PASS, RUN_COLOURS,
                                        UNMEASURED, LiveChange, _mark_changes, heading, judge,
                                        live_changes, read_tuning, verdict_rows)
from ato_nodes.bags.bagio import Run
from ato_nodes.reports.report import write_report
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, scenario_names
from ato_nodes.core.scoring.operation import drive_modes, windowed_jerk
from ato_nodes.reports.report_html import mode_segments, time_figure


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


@pytest.mark.slow
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


@pytest.mark.slow
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
    changes = sum(a[1] != b[1] for a, b in zip(starts, starts[1:], strict=False))
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


@pytest.mark.slow
def test_every_shipped_scenario_names_indices_the_scorer_gives():
    for name in scenario_names():
        parameters = load_scenario(name)
        judge(Run(Path(name), {"t": np.zeros(2), "target": np.zeros(2),
                               "speed": np.zeros(2)}, parameters, {}))  # raises if misnamed


def metro_values(*overrides):
    return apply_overrides(load_scenario("seed004-metro"), list(overrides))


@pytest.mark.slow
def test_a_live_change_shows_in_the_gains_a_table_and_the_time_plots(tmp_path):
    values = metro_values()
    changes = {592: {"dadrc.b1": 100.0}}  # `ros2 param set /controller dadrc.b1 100.0`
    path = tmp_path / "live"
    path.mkdir()
    run = Run(path, simulate(values, changes=changes), values, {}, parameter_changes=changes)
    assert live_changes(run) == [LiveChange(592, pytest.approx(59.2), "dadrc.b1", 40.0, 100.0)]
    assert "b1 40 -> 100 at 59.2 s" in judge(run).identity["gains"]
    markdown, page = write_report([run], [], tmp_path / "report")
    text = markdown.read_text()
    assert "## Live parameter changes" in text
    assert "| live | 592 | 59.2 | dadrc.b1 | 40 -> 100 |" in text
    assert "b1 40 -> 100 at 59.2 s" in text
    html_text = page.read_text()
    assert "<td>dadrc.b1</td><td>40 -&gt; 100</td>" in html_text
    figure = time_figure([judge(run)])
    marks = [shape for shape in figure.layout.shapes if shape.x0 == shape.x1 == 59.2]
    assert len(marks) == len({shape.yref for shape in marks}) > 5  # on every time subplot
    assert any("dadrc.b1 40 -&gt; 100 at 59.2 s" == a.text for a in figure.layout.annotations)


def test_the_png_time_plots_mark_a_live_change():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    run = Run(Path("live"), {}, {"run.period": 0.1, "dadrc.b1": 40.0}, {},
              parameter_changes={592: {"dadrc.b1": 100.0}})
    figure, axes = plt.subplots()
    _mark_changes(axes, run, "blue")
    (line,) = axes.get_lines()
    assert list(line.get_xdata()) == [pytest.approx(59.2)] * 2
    assert line.get_label() == "live: dadrc.b1 40 -> 100 at 59.2 s"
    plt.close(figure)


@pytest.fixture(scope="module")
def metro_start(tmp_path_factory):
    """The metro run cut by --duration 30: it ends 2.4 km before its stop, moving."""
    return make_run(tmp_path_factory.mktemp("start"), "metro-start", ["run.duration=30"])


def test_a_run_that_ends_before_its_stop_has_its_stop_not_judged_and_says_why(metro_start):
    report = judge(metro_start)
    assert report.indices["abs_stopping_error"] > 2000
    for key in ("abs_stopping_error", "running_time_error"):
        status, why = report.judged(key)
        assert status == UNMEASURED
        assert why == "the run ended at t = 29.9 s, 2414 m before its stop, still moving at " \
                      "53 km/h"
    overall, text = report.summary
    assert overall == FAIL  # max abs(e) 1.77 > 1 km/h: broken whatever follows
    assert "broken: max abs(e) km/h 1.7672 > 1; not judged: abs(stopping error) m, " \
           "run-time error s (the run ended at t = 29.9 s, 2414 m before its stop" in text
    assert "2414" not in text.split("not judged")[0]


def test_a_train_standing_short_of_its_stop_is_judged(metro):
    series = {**metro.series, "position": metro.series["position"] - 100.0}
    report = judge(Run(metro.path, series, metro.parameters, {}))
    assert report.status("abs_stopping_error") == FAIL
    assert "abs(stopping error) m 99.737 > 0.3" in report.summary[1]  # +0.263 m, less 100


def test_a_partial_run_fails_only_what_it_cannot_mend_and_says_where_it_stopped(tmp_path):
    values = metro_values()
    series = simulate(values)
    cut = {name: column[:990] for name, column in series.items()}  # 99 s of 200
    report = judge(Run(tmp_path, cut, values, {}, status="timeout"))
    assert report.partial == "timed out at step 990 of 2000"
    assert report.status("max_abs_error_kmh") == FAIL  # a maximum only grows
    assert report.judged("switch_count") == (UNMEASURED, "met over the steps recorded, but "
                                                         "the run is partial")
    assert report.summary[1].startswith(f"{tmp_path.name} (partial: timed out at step 990 of "
                                        "2000): ")
    assert "partial: timed out at step 990 of 2000" in report.identity["run"]
    assert Run(tmp_path, cut, values, {}).partial == "interrupted at step 990 of 2000"
    assert Run(tmp_path, series, values, {}, status="interrupted").partial is None


def test_every_index_heading_names_its_unit():
    unitless = {"steps", "j_seed004", "switch_count", "overrun"}  # counts; J adds unlike terms
    for key, title, _ in INDEX_COLUMNS:
        if key not in unitless:
            assert re.search(r"(km/h|m/s\^3|m/s\^2|m/s|kWh|\bs\b|\bm\b|%|s\^2|m\^2/s)$",
                             title), title
    assert heading("eso_disturbance_max_dev") == "max abs(z3-f) m/s^3"


def test_the_convergence_plot_names_its_fitness_and_unit(tmp_path):
    tuning = tmp_path / "tune"
    tuning.mkdir()
    (tuning / "history.csv").write_text("iteration,evaluations,best_fitness,mean_fitness,x\n"
                                        "0,4,120.5,130.0,1.0\n1,8,99.25,110.0,2.0\n")
    (tuning / "tuning.json").write_text(json.dumps({"fitness": "itae"}))
    read = read_tuning(tuning)
    assert (read.evaluations, read.best) == ([4, 8], [120.5, 99.25])
    assert read.axis_title == "best fitness: ITAE (m/s) s^2"
    (tuning / "tuning.json").write_text(json.dumps({"fitness": "j"}))
    assert read_tuning(tuning).axis_title == "best fitness: J (seed 004)"
    _, page = write_report([], [tuning], tmp_path / "report")
    assert (tmp_path / "report" / "convergence.png").stat().st_size > 0
    assert "best fitness: J (seed 004)" in page.read_text()


def test_the_speed_limit_is_drawn_unlike_any_run_and_the_legend_clears_the_titles(
        metro, tmp_path):
    runs = [metro, make_run(tmp_path, "tuned", ["dadrc.b1=60"])]
    figure = time_figure([judge(run) for run in runs])
    lines = {trace.name: trace.line for trace in figure.data if trace.name}
    limit = lines["speed limit"]
    assert limit.dash == "dashdot"
    assert all(lines[f"{run.path.name} speed"].color != limit.color for run in runs)
    assert LIMIT_COLOUR not in RUN_COLOURS
    first_title = figure.layout.annotations[0]
    assert first_title.text.startswith("speed (km/h)") and first_title.y == pytest.approx(1.0)
    plot_height = figure.layout.height - figure.layout.margin.t - figure.layout.margin.b
    assert figure.layout.legend.yanchor == "bottom"
    assert (figure.layout.legend.y - first_title.y) * plot_height >= 25  # px: the title's room
