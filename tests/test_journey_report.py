"""The report of a journey run (analyze.py): the per-station and per-section tables, the
journey's verdict and speed against position, from a short journey run in-process, and
a bag's kept timetable read on another machine."""

import base64
import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.bags.bagio import Run, resimulate
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.units import MS_TO_KMH
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import (LINE_BASE64, encode_line, kept_files,
                                      limit_where_the_train_is, run_line)
from ato_nodes.core.targets.timetable import load_timetable
from ato_nodes.core.train.line import Section
from ato_nodes.results.journeys import (TIMETABLE, WORST_ARRIVAL, WORST_STOP, run_journey,
                                        run_timetable, score_run, score_with_journey,
                                        worst_stations)
from ato_nodes.reports.report import write_report
from ato_nodes.core.targets.restriction import NAME as RESTRICTION
from ato_nodes.reports.report_journey import (NO_REPLANS, REPLANS, journey_figure, journey_reports,
                                              limit_steps, station_rows)
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.targets.served import replans
from ato_nodes.reports.analysis import judge

DURATION = 300.0  # s: Market and Riverside reached, Central (arrival 422 s) not


@pytest.fixture(scope="module")
def journey(tmp_path_factory):
    values = apply_overrides(load_scenario("seed004-metro-line"), [f"run.duration={DURATION}"])
    path = tmp_path_factory.mktemp("runs") / "line"
    path.mkdir()
    (path / "summary.json").write_text(json.dumps({"scenario": "seed004-metro-line"}))
    return Run(path, simulate(values), values, {})


def standstill_near(series, mark: float) -> tuple[int, int]:
    """(first, last) sample of the last standstill within 50 m of `mark`."""
    near = (series["speed"] <= 0.01) & (np.abs(series["position"] - mark) <= 50.0)
    last = int(np.flatnonzero(near)[-1])
    first = last
    while first > 0 and near[first - 1]:
        first -= 1
    return first, last


def table_row(text: str, station: str) -> list[str]:
    row = next(line for line in text.splitlines() if line.startswith(f"| {station}"))
    return [cell.strip() for cell in row.strip("|").split(" | ")]


@pytest.mark.slow
def test_the_report_tables_each_station_and_section_of_the_timetable(journey, tmp_path):
    markdown, page = write_report([journey], [], tmp_path / "report")
    text, series = markdown.read_text(), journey.series
    timetable = load_timetable(journey.parameters[TIMETABLE])
    market, riverside = timetable.stops[1], timetable.stops[2]
    first, last = standstill_near(series, market.position)
    row = table_row(text, "Market (synthetic)")
    assert row[2] == f"{series['position'][last] - market.position:+.3f}"
    assert row[3] == f"{series['t'][first]:.1f}"
    assert float(row[4]) == pytest.approx(series["t"][first] - market.arrival, abs=0.051)
    assert float(row[5]) == pytest.approx(series["t"][last + 1], abs=0.051)
    assert float(row[7]) == pytest.approx(series["t"][last + 1] - series["t"][first], abs=0.11)
    assert row[8] == "pass"  # the in-process run meets both requirements here
    assert table_row(text, "Riverside (synthetic)")[8] == "pass"
    assert "not judged" in table_row(text, "Central (synthetic)")[8]  # the run ended before
    assert "**NOT JUDGED** 2 of 6 stations met, 4 not judged; worst stop" in text
    section = table_row(text, "Market (synthetic) - Riverside (synthetic)")
    leave = standstill_near(series, market.position)[1] + 1
    arrive = standstill_near(series, riverside.position)[0]
    assert float(section[2]) == pytest.approx(series["t"][arrive] - series["t"][leave], abs=0.11)
    assert section[3] == f"{riverside.arrival - market.departure:g}"
    assert float(section[5]) > 0
    assert table_row(text, "Riverside (synthetic) - Central (synthetic)")[2] == "-"
    assert "![Journey, speed against position: line](journey_1.png)" in text
    assert (tmp_path / "report" / "journey_1.png").stat().st_size > 0
    html = page.read_text()
    assert len(re.findall(r'class="plotly-graph-div"', html)) == 3  # time, distance, journey
    assert re.search(r"<td>Market \(synthetic\)</td>.*?<td style='background:#d8f3dc'"
                     r"[^>]*>pass</td>", html)
    assert re.search(r"<td style='background:#fff3bf' title='the run ended at t = [0-9.]+ s, "
                     r"[0-9.]+ m short of the mark, before a stop'>not judged</td>",
                     html)


@pytest.mark.slow
def test_the_report_lists_the_replans_the_bag_recorded(journey, tmp_path):
    """A train held 20 s longer at Market leaves it late: the one re-plan, recorded as the
    profile node records it (its fields and step), is listed in report.md and report.html
    in the profile's words with its time; a run without one says so."""
    values = apply_overrides(journey.parameters, ["profile.journey.dwell_extension=2:20"])
    series = simulate(values)
    (made,) = replans(RunContext(values).plan, values["run.period"], series["position"])
    delayed = Run(journey.path, series, values, {})
    delayed.replans = [{"step": round(made.time / values["run.period"]), **made._asdict()}]
    markdown, page = write_report([delayed], [], tmp_path / "delayed")
    said = f"t = {made.time:.1f} s: {made.text()}"
    assert made.origin == "Market (synthetic)" and made.lateness > 19.0
    assert f"{REPLANS}:\n\n- {said}" in markdown.read_text()
    assert f"<li>{said}</li>" in page.read_text()
    markdown, page = write_report([journey], [], tmp_path / "on-time")
    assert NO_REPLANS in markdown.read_text() and REPLANS not in markdown.read_text()


def test_the_plot_shows_the_line_its_stations_and_the_planned_and_driven_speed(journey):
    (report,), _ = journey_reports([judge(journey)])
    line = dataclasses.replace(report.line, neutral_sections=(Section(2000.0, 2100.0, 0.0),))
    shaded = dataclasses.replace(report, line=line)
    figure = journey_figure(shaded)
    traces = {trace.name: trace for trace in figure.data}
    limits = traces["line speed limit"]
    for section in line.speed_limits:  # each limit over its whole extent, in km/h
        middle = (section.start + section.end) / 2000
        assert np.interp(middle, limits.x, limits.y) == pytest.approx(section.value * MS_TO_KMH)
    driven, planned = traces["line driven"], traces["planned (target)"]
    assert np.allclose(driven.x, journey.series["position"] / 1000, rtol=1e-6)
    assert np.allclose(driven.y, journey.series["speed"] * MS_TO_KMH, atol=1e-4)
    assert np.allclose(planned.y, journey.series["target"] * MS_TO_KMH, atol=1e-4)
    shapes = figure.layout.shapes
    assert [s.x0 for s in shapes if s.type == "rect"] == [2.0]
    assert sorted(s.x0 for s in shapes if s.type == "line") == pytest.approx(
        [station.position / 1000 for station in line.stations])


def test_the_plot_draws_a_temporary_speed_restriction_of_the_run(journey):
    restricted = Run(journey.path, journey.series,
                     {**journey.parameters, RESTRICTION: "1000:1400:8.33"}, {})
    (report,), _ = journey_reports([judge(restricted)])
    limits = journey_figure(report).data[0]
    assert limits.name == "line speed limit"
    assert np.interp(1.2, limits.x, limits.y) == pytest.approx(8.33 * MS_TO_KMH)
    (unrestricted,), _ = journey_reports([judge(journey)])
    assert np.interp(1.2, *limit_steps(unrestricted.line)) > 8.33 * MS_TO_KMH + 1.0


def moved(run: Run, tmp_path: Path, keep: bool = True) -> Run:
    """The run as its bag reads on another machine: the line and (if `keep`) the timetable
    kept in it, neither file where the run found it."""
    values = run.parameters
    kept = {LINE_BASE64: encode_line(Path(values["line.file"]).read_text()),
            **(kept_files(values) if keep else {})}
    gone = tmp_path / "elsewhere"
    return Run(run.path, run.series, {**values, **kept, "line.file": str(gone / "line.yaml"),
                                      TIMETABLE: str(gone / "metro-line.yaml")}, {})


def test_a_bag_moved_to_another_machine_is_scored_on_the_timetable_it_keeps(journey, tmp_path):
    here = journey_reports([judge(journey)])[0][0]
    elsewhere = moved(journey, tmp_path)
    assert run_timetable(elsewhere.parameters).stops == here.timetable.stops
    (there,), notes = journey_reports([judge(elsewhere)])
    assert station_rows(there.indices) == station_rows(here.indices) and not notes  # NaNs
    # overspeed judged where the train was, from the plan the bag's copies make again,
    # not from the limit recorded where the ATO had it (here misread: 0.5 m/s)
    misread = {**journey.series, "speed_limit": np.full(len(journey.series["t"]), 0.5)}
    true_limit = limit_where_the_train_is(misread, journey.parameters,
                                          run_line(journey.parameters))
    assert np.array_equal(limit_where_the_train_is(
        misread, elsewhere.parameters, run_line(elsewhere.parameters)), true_limit)
    assert true_limit.min() > 0.5
    journeys, notes = journey_reports([judge(moved(journey, tmp_path, keep=False))])
    assert not journeys and "neither kept in the bag nor on this machine" in notes[0]
    tampered = dict(elsewhere.parameters)
    tampered[f"{TIMETABLE}.base64"] = base64.b64encode(b"stops: []").decode()
    with pytest.raises(ScenarioError, match=r"^the copy of profile.journey.timetable kept in "
                                            r"the bag does not match its sha256$"):
        run_timetable(tampered)


@pytest.mark.slow
def test_a_run_lacking_a_series_is_noted_and_other_runs_have_no_journey(journey, tmp_path):
    series = {name: values for name, values in journey.series.items() if name != "force"}
    journeys, notes = journey_reports([judge(Run(journey.path, series, journey.parameters,
                                                 {}))])
    assert not journeys and re.search(r"no per-station table: .*need the series force", notes[0])
    values = apply_overrides(load_scenario("seed004-metro"), ["run.duration=20"])
    markdown, _ = write_report([Run(tmp_path, simulate(values), values, {})], [],
                               tmp_path / "report")
    assert "## Journey" not in markdown.read_text()



def test_a_study_counts_a_journey_by_its_worst_station(journey):
    series, values = journey.series, journey.parameters
    timetable = run_timetable(values)
    cut = worst_stations(run_journey(series, values, timetable))
    assert cut == {WORST_STOP: np.inf, WORST_ARRIVAL: np.inf}  # Central not reached
    reached = dataclasses.replace(timetable, stops=timetable.stops[:3])
    worst = worst_stations(run_journey(series, values, reached))
    stops = [(stop, standstill_near(series, stop.position)) for stop in reached.stops[1:]]
    assert worst[WORST_STOP] == pytest.approx(max(
        abs(series["position"][last] - stop.position) for stop, (_, last) in stops))
    assert worst[WORST_ARRIVAL] == pytest.approx(max(
        abs(series["t"][first] - stop.arrival) for stop, (first, _) in stops))


def test_a_journey_bag_runs_again_from_its_kept_line_and_timetable_of_one_name(journey,
                                                                               tmp_path):
    """The line and the timetable are both metro-line.yaml: each copy keeps its own."""
    values = moved(journey, tmp_path).parameters
    values["line.file"] = str(tmp_path / "elsewhere" / "metro-line.yaml")
    series, differ = resimulate(Run(journey.path, journey.series, values, {}))
    assert differ == [] and len(series["t"]) == len(journey.series["t"])


def test_a_study_scores_a_journey_that_ends_before_the_lines_last_station_at_its_last_stop(
        tmp_path):
    """The line's last station is kilometres on: a study's stop indices are the
    timetable's last stop's, as score_bag's are."""
    line = Path(__file__).resolve().parents[1] / "msg_config" / "lines" / "metro-line.yaml"
    (tmp_path / "short.yaml").write_text(f"""line: {line}
train: metro-b
load: 1.3
stops:
  - {{station: Westgate (synthetic), departure: 0}}
  - {{station: Market (synthetic), arrival: 131, departure: 156}}
  - {{station: Riverside (synthetic), arrival: 281}}
""")
    values = apply_overrides(load_scenario("seed004-metro-line"), [
        f"{TIMETABLE}={tmp_path / 'short.yaml'}"])
    indices = score_with_journey(values)
    # scored at Riverside, not kilometres short of the line's last station; one of the
    # journey's stops, so no worse than its worst
    assert abs(indices["stopping_error"]) <= indices[WORST_STOP] < 0.1
    assert indices["stopping_error"] == score_run(simulate(values), values)["stopping_error"]
