"""A journey's results in the run's machine-readable files and on the console: every
station's stop error, arrival and departure lateness, dwell and verdict in summary.json,
score_bag (text and --json), analyze's indices.json and run_stack's end-of-run print,
from the one per-station scorer (core/scoring/journey.py); its stopping error and
arrival time are its last stop's, none when the train did not stop there. Bags written
in-process; one run through the stack."""

import json
import math
import subprocess
import sys

import pytest

from ato_nodes.results import jsontext
from ato_nodes.cli import score_bag
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import kept_files, score_series
from ato_nodes.core.scoring.catalogue import STOP_INDICES, format_indices
from ato_nodes.core.scoring.journey import (NOT_JUDGED, NOT_REACHED, STOPPED, format_journey,
                                            journey_record)
from ato_nodes.results.journeys import TIMETABLE, run_journey, run_timetable, score_run
from ato_nodes.reports.report import write_report
from ato_nodes.bags.bagio import read_run
from ato_nodes.bags.summary import bag_contents
from bagfile import write_run_bag
from commands import ROOT, invocation

SCENARIO = "seed004-metro-line"
CUT = 300.0  # s: Market and Riverside reached, Central (arrival 432 s) and beyond not
ROW_FIELDS = {"station", "mark", "outcome", "stop_error", "arrival", "departure",
              "arrival_lateness", "departure_lateness", "dwell", "verdict", "reason"}


def as_json(value):
    return json.loads(jsontext.dumps(value))


def journey_bag(path, overrides):
    """A journey's run in-process, as the stack's bag keeps it (the line and the
    timetable's copies among its parameters): (bag, series, values)."""
    values = prepare(SCENARIO, overrides)
    series = simulate(values)
    return write_run_bag(path, series, {**values, **kept_files(values)},
                         status="completed"), series, values


@pytest.fixture(scope="module")
def cut(tmp_path_factory):
    return journey_bag(tmp_path_factory.mktemp("bags") / "cut", [f"run.duration={CUT}"])


def two_stops(tmp_path) -> str:
    """The metro line's first section alone: its last stop Market, not the line's last
    station (Depot Road, where an interstation run stops)."""
    path = tmp_path / "two-stops.yaml"
    path.write_text("line: lines/metro-line.yaml\ntrain: metro-b\nstops:\n"
                    "  - {station: Westgate (synthetic), departure: 0}\n"
                    "  - {station: Market (synthetic), arrival: 128}\n")
    return str(path)


def test_every_station_is_a_row_of_the_one_per_station_scorer(cut):
    run = read_run(cut[0])
    indices = score_run(run.series, run.parameters)
    timetable = run_timetable(run.parameters)
    expected = journey_record(run_journey(run.series, run.parameters, timetable))
    assert as_json(indices["journey"]) == as_json({"timetable": "metro-line.yaml", **expected})
    rows = indices["journey"]["stations"]
    assert [row["station"] for row in rows] == [stop.station for stop in timetable.stops]
    assert all(set(row) == ROW_FIELDS for row in rows)
    reached = [row for row in rows if row["outcome"] == STOPPED]
    assert [row["station"] for row in reached] == [s.station for s in timetable.stops[:3]]
    for row in rows[3:]:
        assert row["outcome"] == NOT_REACHED and row["verdict"] == NOT_JUDGED
        assert math.isnan(row["stop_error"]) and "short of the mark" in row["reason"]
    market = rows[1]
    assert market["dwell"] == pytest.approx(market["departure"] - market["arrival"])
    assert market["arrival_lateness"] == pytest.approx(
        market["arrival"] - timetable.stops[1].arrival)


def test_a_cut_journeys_stop_indices_are_none_not_the_distance_to_the_line_end(cut):
    bag, series, values = cut
    plain = score_series(series, values)
    assert plain["stopping_error"] < -8000  # what the whole run alone says
    indices = score_run(series, values)
    assert all(math.isnan(indices[key]) for key in STOP_INDICES if key in plain)
    assert {key: value for key, value in indices.items() if key not in STOP_INDICES
            and key != "journey"} == {key: value for key, value in plain.items()
                                      if key not in STOP_INDICES}


@pytest.mark.slow
def test_summary_json_score_bag_json_and_indices_json_hold_the_same_rows(cut, tmp_path,
                                                                          monkeypatch, capsys):
    bag = cut[0]
    summary = as_json(bag_contents(bag))["indices"]
    assert summary["stopping_error"] is None and summary["arrival_time"] is None
    assert summary["journey"]["stations"][-1]["reason"].startswith("the run ended at")
    monkeypatch.setattr(sys, "argv", ["score_bag", str(bag), "--json"])
    score_bag.main()
    assert json.loads(capsys.readouterr().out) == summary
    write_report([read_run(bag)], [], tmp_path / "report")
    indices = json.loads((tmp_path / "report" / "indices.json").read_text())[bag.name]
    assert {key: value for key, value in indices.items() if key != "skipped"} == summary


def test_score_bags_text_names_the_last_stop_not_reached_and_lists_every_station(
        cut, monkeypatch, capsys):
    bag, _, values = cut
    monkeypatch.setattr(sys, "argv", ["score_bag", str(bag)])
    score_bag.main()
    text = capsys.readouterr().out
    assert "stopping error   not reached: Depot Road (synthetic), the last stop" in text
    assert "arrival time     not reached: Depot Road (synthetic), the last stop" in text
    assert "-8050" not in text
    for stop in run_timetable(values).stops:
        assert sum(line.startswith(f"  {stop.station} ") for line in text.splitlines()) == 1
    assert "journey          metro-line.yaml: NOT JUDGED: 2 of 6 stations met" in text


def test_a_journeys_stop_indices_are_its_timetables_last_stop(tmp_path):
    """A journey that ends at Market, short of the line's last station: its stopping
    error is Market's, not the distance to Depot Road."""
    bag, series, values = journey_bag(tmp_path / "two", [f"{TIMETABLE}={two_stops(tmp_path)}",
                                                         "run.duration=300"])
    indices = score_run(read_run(bag).series, read_run(bag).parameters)
    market = indices["journey"]["stations"][-1]
    assert market["station"] == "Market (synthetic)" and market["outcome"] == STOPPED
    assert score_series(series, values)["stopping_error"] < -9000
    assert indices["stopping_error"] == market["stop_error"]
    assert indices["abs_stopping_error"] == abs(market["stop_error"]) < 0.1
    assert indices["arrival_time"] == market["arrival"]
    text = format_indices(indices)
    assert f"stopping error   {market['stop_error']:+.3f} m at Market (synthetic), the last " \
           "stop" in text


def test_a_journey_without_its_timetable_judges_no_stop_and_says_why(cut):
    _, series, values = cut
    nowhere = {**values, TIMETABLE: "/nonexistent/metro-line.yaml"}
    indices = score_run(series, nowhere)
    assert all(math.isnan(indices[key]) for key in STOP_INDICES if key in indices)
    assert "neither kept in the bag nor on this machine" in indices["journey"]["error"]
    assert "stopping error   not judged: the last stop (no per-station results)" in \
        format_indices(indices)


def test_an_interstation_run_is_scored_as_before(tmp_path):
    values = prepare("seed004-metro", ["run.duration=30"])
    series = simulate(values)
    indices = score_run(series, values)
    assert "journey" not in indices
    assert as_json(indices) == as_json(score_series(series, values))
    assert "the last stop" not in format_indices(indices)


def test_the_console_rows_read_the_same_from_the_json_files(cut):
    _, series, values = cut
    record = score_run(series, values)["journey"]
    assert format_journey(as_json(record)) == format_journey(record)
    assert len(format_journey(record)) == 2 + len(record["stations"])


@pytest.mark.integration
def test_the_stacks_summary_json_and_print_hold_each_station_of_a_cut_journey(tmp_path,
                                                                             ros_domain):
    bag, overrides = tmp_path / "cut", [f"run.duration={CUT}"]
    done = subprocess.run([*invocation("run_stack"), "--scenario", SCENARIO, "--out",
                           str(bag), "--quiet", "--domain-id", str(ros_domain.domain_id),
                           *(f"--set={item}" for item in overrides)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT,
                          **ros_domain.handed_down())
    assert done.returncode == 0, done.stdout + done.stderr
    run, values = read_run(bag), prepare(SCENARIO, overrides)
    summary = json.loads((bag / "summary.json").read_text())["indices"]
    assert summary["journey"] == as_json(score_run(run.series, run.parameters))["journey"]
    in_process = score_run(simulate(values), values)["journey"]["stations"]
    assert [(row["outcome"], row["verdict"]) for row in summary["journey"]["stations"]] == \
        [(row["outcome"], row["verdict"]) for row in in_process]
    assert summary["stopping_error"] is None and summary["arrival_time"] is None
    assert "stopping error   not reached: Depot Road (synthetic)" in done.stdout
    for row in summary["journey"]["stations"]:
        assert f"  {row['station']} " in done.stdout
    scored = subprocess.run([*invocation("score_bag"), str(bag), "--json"],
                            capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert json.loads(scored.stdout) == summary


def test_a_journey_lacking_a_series_says_which_instead_of_failing(cut, tmp_path):
    """On a line with a neutral section, which is looked for at the positions."""
    line = tmp_path / "metro-neutral.yaml"
    line.write_text((ROOT / "msg_config" / "lines" / "metro-line.yaml").read_text()
                    + "neutral_sections:\n  - {start: 2500.0, end: 2600.0}\n")
    _, series, values = cut
    without = {name: data for name, data in series.items() if name != "position"}
    journey = score_run(without, {**values, "line.file": str(line)})["journey"]
    assert journey["timetable"] == "metro-line.yaml"
    assert "need the series position" in journey["error"]


def test_a_journey_run_to_its_end_keeps_its_stop_indices():
    """Ended at its last stop, the line's last station: the stop indices are the whole
    run's as before, and the last station's row."""
    values = prepare(SCENARIO, [])
    series = simulate(values)
    plain, indices = score_series(series, values), score_run(series, values)
    assert {key: indices[key] for key in STOP_INDICES if key in plain} == \
        {key: plain[key] for key in STOP_INDICES if key in plain}
    last = indices["journey"]["stations"][-1]
    assert (last["stop_error"], last["arrival"]) == (plain["stopping_error"],
                                                     plain["arrival_time"])
    assert indices["journey"]["verdict"] == last["verdict"] == "pass"


def test_the_report_does_not_fail_a_cut_journey_on_the_stop_it_never_reached(cut, tmp_path):
    markdown, _ = write_report([read_run(cut[0])], [], tmp_path / "report")
    text = markdown.read_text()
    assert "- **NOT JUDGED** cut: 3 of 4 requirements met; not judged: abs(stopping error) m " \
           "(Depot Road (synthetic), the last stop: not reached (the run ended" in text
    assert "| abs(stopping error) m | <= 0.1 | - (not reached) not judged |" in text
    assert "| arrival s |  | - (not reached) |" in text
