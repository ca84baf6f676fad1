"""Journeys of timing points: a TTOBench journey file as a timetable
(core/targets/timetable.py), its sections planned to their passing points' windows
(core/targets/served.py) and every timing point judged (core/scoring/journey.py)."""

import dataclasses
import json
import shutil
import subprocess

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.paths import config_dir
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.scoring.journey import (ARRIVAL, DEPARTURE, FAIL, NOT_JUDGED, PASS, PASSING,
                                            journey_indices, journey_record)
from ato_nodes.core.targets import served
from ato_nodes.core.targets.timetable import (JOURNEYS, Window, check_running_times,
                                              journey_file, journey_on, load_timetable)
from ato_nodes.core.train.line import Line, Section
from ato_nodes.core.train.plant import TrainParameters
from ato_nodes.core.train.ttobench import Journey, TimingPoint, load_train
from ato_nodes.results.journeys import (TIMETABLE, TIMING_MISSED, WORST_ARRIVAL, run_timetable,
                                        score_run, worst_stations)
from ato_nodes.bags.bagio import read_run
from ato_nodes.results import jsontext
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import kept_files
from bagfile import write_run_bag
from commands import ROOT, invocation
from commands import run_stack as stack_run

SHIPPED = JOURNEYS / "CH_StGallen_Wil_Journey_01.json"
DT = 0.1  # s, the synthetic runs' period


def kiss() -> dict:
    """A run's values with the SBB KISS as the plant and an on-time ato curve."""
    values = defaults()
    train = load_train(config_dir() / "ttobench" / "trains" / "CH_Stadler_KISS_SBB.json")
    values.update(train.plant_values(values["plant.gravity"]))
    values.update({"profile.ato.on_time": True, "profile.envelope_share": 0.9,
                   "profile.jerk": 0.5, "profile.ato.start_speed": 0.1,
                   "profile.ato.acceleration": 0.6, "profile.ato.deceleration": 0.6,
                   "profile.journey.recovery": 5.0, "profile.journey.catch_up": 0})
    return values


def test_a_ttobench_journey_is_a_timetable_of_windows():
    timetable = load_timetable(SHIPPED)
    first, middle, last = timetable.stops
    assert (first.departure, middle.arrival, middle.departure, last.arrival) == (
        0.0, 680.0, 800.0, 1450.0)  # arriving at the latest, departing at the earliest
    assert middle.arrival_window == Window(620.0, 680.0)
    assert middle.departure_window == Window(800.0, 840.0)
    assert middle.least_dwell == 120.0 and middle.station == "km 15"
    assert [s.running_time for s in timetable.sections] == [680.0, 650.0]
    (one,), (two,) = (section.passing for section in timetable.sections)
    assert (one.name, one.position, one.window, one.min_speed) == (
        "km 12.5", 12500.0, Window(480.0, 540.0), pytest.approx(10 / 3.6))
    assert two.window == Window(1200.0, 1250.0) and two.min_speed is None
    assert timetable.journey == "CH_StGallen_Wil_Journey_01" and timetable.for_train("any")
    assert timetable.where(3) == "timing points entry 3"


def test_a_window_tells_how_far_outside():
    window = Window(10.0, 20.0)
    assert [window.miss(t) for t in (5.0, 10.0, 20.0, 26.5)] == [-5.0, 0.0, 0.0, 6.5]
    assert Window(None, 20.0).miss(-1e9) == 0.0 and Window(10.0, None).miss(1e9) == 0.0


def test_a_journey_is_given_by_its_file_from_anywhere_or_its_id(tmp_path):
    assert journey_file("CH_StGallen_Wil_Journey_01") == str(SHIPPED)
    copy = tmp_path / "elsewhere" / "mine.json"  # no tracks/ beside it: the shipped track
    copy.parent.mkdir()
    shutil.copy(SHIPPED, copy)
    assert journey_file(str(copy)) == str(copy)
    assert load_timetable(copy).stops == load_timetable(SHIPPED).stops
    with pytest.raises(ScenarioError, match="unknown TTOBench journey 'nowhere'"):
        journey_file("nowhere")


def edited(tmp_path, rows) -> str:
    document = json.loads(SHIPPED.read_text())
    document["timing points"]["values"] = rows
    path = tmp_path / "journey.json"
    path.write_text(json.dumps(document))
    return str(path)


def test_bad_journeys_are_one_line_naming_the_file_and_entry(tmp_path):
    untimed = edited(tmp_path, [[0, 0, 0, 0, 0], [15000, None, None, 0, 0]])
    with pytest.raises(ScenarioError, match=r"journey.json: timing points entry 2: a stop "
                       "needs a lower or an upper time constraint"):
        load_timetable(untimed)
    far = edited(tmp_path, [[0, 0, 0, 0, 0], [15000, 100, 1e9, 0, 0]])
    with pytest.raises(ScenarioError, match=r"journey.json: timing points entry 2: a time more "
                       r"than 604800 s \(7 days\)"):
        load_timetable(far)
    # departing at 200 s (its arrival's latest, after its own earliest 150 s), then due
    # at the next stop by 200 s: the library's rules allow it, the planner has no time
    no_time = edited(tmp_path, [[0, 0, 0, 0, 0], [5000, 100, 200, 0, 0], [5000, 150, 300, 0, 0],
                                [15000, 180, 200, 0, 0]])
    with pytest.raises(ScenarioError, match=r"journey.json: timing points entry 4: the arrival "
                       "200 s at 15000 m is not after the departure 200 s from km 5"):
        load_timetable(no_time)
    tight = load_timetable(edited(tmp_path, [[0, 0, 0, 0, 0], [15000, 100, 200, 0, 0]]))
    with pytest.raises(ScenarioError, match=r"journey.json timing points entry 2: the running "
                       "time 200 s from km 0 to km 15 is below its minimum"):
        check_running_times(tight, kiss())
    track = tmp_path / "tracks" / "CH_StGallen_Wil.json"  # the library's layout: ../tracks
    track.parent.mkdir()
    track.write_text("{")
    (tmp_path / "journeys").mkdir()
    beside = tmp_path / "journeys" / "journey.json"
    shutil.copy(SHIPPED, beside)
    with pytest.raises(ScenarioError, match=r"tracks/CH_StGallen_Wil.json line 1: malformed"):
        load_timetable(beside)


def test_the_planner_keeps_a_passing_window_or_says_it_cannot():
    values = kiss()
    timetable = load_timetable(SHIPPED)
    train = TrainParameters.from_values(values)
    table, notice = served.new_journey_table(timetable, values, timetable.line, train)
    first, second = timetable.sections
    own = served.section_line(timetable.line, first.start, first.end)
    planned = dataclasses.replace(own, planned_run_time=675.0)
    uncapped = served.ato_curve(values, planned, train)
    assert uncapped.passing_time(12500.0) > 540.0  # a single cruise passes too late
    curve, said = served.timed_curve(values, planned, train, first, 0.0)
    assert said == [] and not curve.notice
    low, high = served.passing_window(first.passing[0], 0.0, 5.0)
    assert (low, high) == (485.0, 535.0)
    assert high - 1.0 < curve.passing_time(12500.0) <= high + served.CAP_TOLERANCE
    assert curve.planned_run_time == pytest.approx(675.0, abs=0.05)  # still on time
    assert table.times[0, 0] == pytest.approx(curve.planned_run_time)
    # the second: 9.6 km after km 20 take longer than its window leaves to the arrival
    assert notice == ("km 15 - km 29.5561: km 20: the window [1200, 1250] s cannot be met "
                      "with the arrival by this train (planned at "
                      f"{notice.split('planned at ')[1].split(' s)')[0]} s); passing it as "
                      "the on-time curve does")


def synthetic(points) -> tuple:
    """A timetable of TimingPoints (position m, earliest, latest, min m/s, max m/s) on a
    flat 3 km line."""
    line = Line("flat", 3000.0, (), (), (), (Section(0.0, 3000.0, 30.0),), (), (), None)
    journey = Journey("flat_1", "TTOBench v1.5", SHIPPED, "flat",
                      tuple(TimingPoint(*point) for point in points))
    return journey_on(journey, line, "")


STOPPING = (0.0, 0.0)
POINTS = [(0.0, 0.0, 0.0, *STOPPING), (500.0, 40.0, 60.0, 5.0, 20.0),
          (1000.0, 90.0, 110.0, *STOPPING), (1000.0, 130.0, 150.0, *STOPPING),
          (2000.0, 230.0, 250.0, *STOPPING)]


def run(legs):
    """Trapezoids: (metres, seconds) legs with 20 s ramps, or a standstill (0, seconds)."""
    knots, speeds = [0.0], [0.0]
    for metres, seconds in legs:
        now = knots[-1]
        if not metres:
            knots.append(now + seconds)
            speeds.append(0.0)
            continue
        cruise = metres / (seconds - 20.0)
        knots += [now + 20.0, now + seconds - 20.0, now + seconds]
        speeds += [cruise, cruise, 0.0]
    t = np.arange(round(knots[-1] / DT) + 1) * DT
    speed = np.interp(t, knots, speeds)
    position = np.concatenate(([0.0], np.cumsum((speed[1:] + speed[:-1]) / 2 * DT)))
    return {"t": t, "position": position, "speed": speed, "target": speed,
            "force": np.zeros_like(t)}


def test_every_timing_point_is_judged():
    timetable = synthetic(POINTS)
    series = run([(1000.0, 100.0), (0.0, 35.0), (1000.0, 120.0), (0.0, 10.0)])
    indices = journey_indices(series, timetable, 300.0)
    kinds = [(p.point, p.kind) for p in indices.timing]
    assert kinds == [("km 0.5", PASSING), ("km 1", ARRIVAL), ("km 1", DEPARTURE),
                     ("km 2", ARRIVAL)]
    passing, arrival, departure, last = indices.timing
    # 125 m in the 20 s ramp to 12.5 m/s, then 375 m at it
    assert passing.time == pytest.approx(50.0) and passing.speed == pytest.approx(12.5)
    assert (passing.verdict, passing.miss, passing.min_speed) == (PASS, 0.0, 5.0)
    assert (arrival.time, arrival.verdict) == (pytest.approx(100.0), PASS)
    assert departure.verdict == PASS and 135.0 <= departure.time <= 135.0 + 1.5 * DT
    assert (last.earliest, last.latest) == (230.0, 250.0)
    assert last.miss == pytest.approx(5.0) and last.verdict == FAIL
    assert last.reason == "+5.0 s outside [230, 250] s"
    station = indices.stations[-1]
    assert station.verdict == FAIL and "arrival +5.0 s outside its window" in station.reason
    assert indices.stations[1].arrival_lateness == 0.0  # inside its window
    assert indices.verdict == FAIL
    assert worst_stations(indices)[TIMING_MISSED] == 1.0
    assert worst_stations(indices)[WORST_ARRIVAL] == pytest.approx(5.0)
    assert [p["kind"] for p in journey_record(indices)["timing_points"]] == [
        PASSING, ARRIVAL, DEPARTURE, ARRIVAL]


def test_a_passing_point_s_speed_bounds_and_a_run_that_ends_before():
    bounded = [list(point) for point in POINTS]
    bounded[1][3] = 15.0  # at least 54 km/h
    series = run([(1000.0, 100.0), (0.0, 35.0), (1000.0, 115.0), (0.0, 10.0)])
    indices = journey_indices(series, synthetic(bounded), 300.0)
    passing = indices.timing[0]
    assert passing.verdict == FAIL and passing.reason == "45.0 km/h below 54 km/h"
    assert all(p.verdict == PASS for p in indices.timing[1:])
    early = {name: values[:300] for name, values in series.items()}  # 30 s: before km 0.5
    cut = journey_indices(early, synthetic(POINTS), 300.0)
    assert {p.verdict for p in cut.timing} == {NOT_JUDGED}
    assert cut.timing[0].reason == "the run ended before it"


def test_a_timetable_file_has_no_timing_points():
    timetable = load_timetable(config_dir() / "timetables" / "metro-line.yaml")
    assert timetable.passing == () and not timetable.journey
    assert all(stop.arrival_window is None for stop in timetable.stops)


def test_a_bag_keeps_the_journey_and_is_judged_on_its_copy(tmp_path):
    values = prepare("stgallen-wil-journey", ["run.duration=750"])  # standing at km 15
    bag = write_run_bag(tmp_path / "bag", simulate(values),
                        {**values, **kept_files(values)}, status="completed")
    run = read_run(bag)
    moved = {**run.parameters, TIMETABLE: str(tmp_path / "gone" / SHIPPED.name)}
    timetable = run_timetable(moved)  # the bag's copy, on the bag's line
    assert timetable.journey == "CH_StGallen_Wil_Journey_01"
    assert timetable.stops == load_timetable(SHIPPED).stops
    record = score_run(run.series, moved)["journey"]
    verdicts = [(p["point"], p["kind"], p["verdict"]) for p in record["timing_points"]]
    assert verdicts == [("km 12.5", PASSING, PASS), ("km 15", ARRIVAL, PASS),
                        ("km 15", DEPARTURE, NOT_JUDGED), ("km 20", PASSING, NOT_JUDGED),
                        ("km 29.5561", ARRIVAL, NOT_JUDGED)]
    assert 535.0 - 1.0 < record["timing_points"][0]["time"] <= 540.0  # 5 s inside


def test_a_refused_journey_is_one_line_in_the_stack_and_in_process(tmp_path):
    tight = edited(tmp_path, [[0, 0, 0, 0, 0], [15000, 100, 200, 0, 0]])
    with pytest.raises(ScenarioError) as refused:
        prepare("stgallen-wil-journey", [f"profile.journey.timetable={tight}"])
    assert "timing points entry 2: the running time 200 s" in str(refused.value)
    bag = tmp_path / "bag"
    done = subprocess.run([*invocation("run_stack"), "--scenario", "stgallen-wil-journey",
                           "--journey", tight, "--out", str(bag)],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert (done.returncode, done.stderr) == (2, f"error: {refused.value}\n")
    assert not bag.exists()


def test_journey_on_a_scenario_that_is_no_journey_names_journey(tmp_path, capsys):
    """seed000 (profile.kind seed000) with --journey: one line naming --journey, not the
    parameter it sets, exit 2, nothing on disk, in-process and through run_stack.py."""
    from ato_nodes.cli.run_stack import checked_values, parse_args
    bag = tmp_path / "bag"
    argv = ["--scenario", "seed000", "--journey", "CH_StGallen_Wil_Journey_01",
            "--out", str(bag)]
    with pytest.raises(SystemExit) as exited:
        checked_values(parse_args(argv))
    said = capsys.readouterr().err
    assert exited.value.code == 2 and said.count("\n") == 1
    assert said.startswith("error: --journey CH_StGallen_Wil_Journey_01: scenario seed000 is "
                           "not a journey (its profile.kind is seed000)")
    assert "profile.journey.timetable" not in said
    done = subprocess.run([*invocation("run_stack"), *argv], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)
    assert (done.returncode, done.stderr) == (2, said)
    assert not bag.exists()


def test_a_journey_kind_on_the_open_track_is_one_line():
    """A TTOBench journey needs a line to be on: without line.file the plan says so."""
    with pytest.raises(ScenarioError, match="profile.kind is journey but line.file is empty"):
        prepare("seed000", ["profile.kind=journey", f"profile.journey.timetable={SHIPPED}"])


@pytest.mark.integration
def test_the_stack_drives_a_ttobench_journey_to_the_in_process_bits(tmp_path):
    overrides = ["run.duration=700"]  # past km 12.5, standing at km 15
    bag = tmp_path / "bag"
    stack_run("stgallen-wil-journey", bag, overrides)
    run, values = read_run(bag), prepare("stgallen-wil-journey", overrides)
    series = simulate(values)
    for name in ("position", "speed", "target", "command"):
        assert np.array_equal(run.series[name], series[name]), name
    recorded = score_run(run.series, run.parameters)["journey"]["timing_points"]
    assert jsontext.dumps(recorded) == jsontext.dumps(
        score_run(series, values)["journey"]["timing_points"])
    assert [p["verdict"] for p in recorded[:2]] == [PASS, PASS]


def test_a_journey_is_checked_on_the_line_as_the_train_runs_it():
    with pytest.raises(ScenarioError, match=r"timing points entry 3: the running time 680 s "
                       r"from km 0 to km 15 is below its minimum 760\.\d s"):
        prepare("stgallen-wil-journey",  # 80 km/h at most: the line capped under its 125
                ["plant.train=ttobench/trains/CN_Beijing_Subway.json"])
    with pytest.raises(ScenarioError, match="is of line .*CH_StGallen_Wil.json, the run's "
                       "line.file is .*CH_Fribourg_Bern.json"):
        prepare("stgallen-wil-journey", ["line.file=ttobench/tracks/CH_Fribourg_Bern.json"])
