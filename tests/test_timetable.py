"""Timetables of journeys: stops on a line with arrival and departure times, checked
against the line and against the train's minimum running time (core/targets/timetable.py)."""

import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.paths import config_dir
from ato_nodes.core.config.scenario import complete
from ato_nodes.core.targets.timetable import (check_minimum_times, load_timetable,
                                              minimum_running_time, section_line)
from ato_nodes.core.train.line import load_line

METRO = complete({"plant.train": "metro-b"}, [])

LINE = """\
name: three stations
length: 3000
gradients:
  - {start: 0, end: 1200, grade: GRADE}
  - {start: 1200, end: 3000, grade: -4}
curves:
  - {start: 1500, end: 1800, radius: 500}
speed_limits:
  - {start: 0, end: 2000, limit: 22.22}
  - {start: 2000, end: 3000, limit: 16.67}
stations:
  - {name: A, position: 0, dwell: 30}
  - {name: B, position: 1200, dwell: 25}
  - {name: C, position: 3000, dwell: 30}
"""

TIMETABLE = """\
line: line.yaml
train: metro-b
stops:
  - {station: A, departure: 100}
  - {station: B, arrival: 200, departure: 230}
  - {station: C, arrival: 400}
"""


def files(tmp_path, timetable=TIMETABLE, grade=0):
    (tmp_path / "line.yaml").write_text(LINE.replace("GRADE", str(grade)))
    path = tmp_path / "timetable.yaml"
    path.write_text(timetable)
    return path


def test_sections_running_times_and_dwells_come_from_the_stops(tmp_path):
    timetable = load_timetable(files(tmp_path))
    assert [s.running_time for s in timetable.sections] == [100.0, 170.0]
    assert [(s.origin, s.destination, s.start, s.end) for s in timetable.sections] == [
        ("A", "B", 0.0, 1200.0), ("B", "C", 1200.0, 3000.0)]
    assert [stop.dwell for stop in timetable.stops] == [0.0, 30.0, 0.0]
    assert timetable.running_time == 270.0 and timetable.train == "metro-b"


def test_a_station_between_two_stops_is_passed(tmp_path):
    text = TIMETABLE.replace("  - {station: B, arrival: 200, departure: 230}\n", "")
    (section,) = load_timetable(files(tmp_path, text)).sections
    assert (section.origin, section.destination, section.running_time) == ("A", "C", 300.0)


@pytest.mark.parametrize("change, line, message", [
    (("arrival: 400", "arrival: 230"), 6, "times do not increase: arrival 230 s at C is not "
     "after the departure 230 s from B"),
    (("departure: 230", "departure: 190"), 5, "times do not increase: departure 190 s from B "
     "is before its arrival 200 s"),
    (("departure: 230", "departure: 220"), 5, "dwell 20 s at B is shorter than the "
     "station's 25 s"),
    (("station: C", "station: Nowhere"), 6, "'Nowhere' is not a station of the line (its "
     "stations: A, B, C)"),
    (("{station: A, departure: 100}", "{station: A, arrival: 50, departure: 100}"), 4,
     "the first stop has no arrival"),
    (("arrival: 200, departure: 230", "arrival: 200"), 5, "a stop on the way needs its "
     "departure"),
    (("{station: B, arrival: 200, departure: 230}\n  - {station: C, arrival: 400}",
      "{station: C, arrival: 200, departure: 230}\n  - {station: B, arrival: 400}"), 6,
     "B is not after C along the line"),
    (("arrival: 400", "arrival: fast"), 6, "arrival must be a finite number"),
    (("stops:", "stop:"), 3, "unknown key 'stop'"),
    (("stops:", "load: 0.8\nstops:"), 3, "load must be from 1 (the nominal train) to 2 "
     "times the train's mass, not 0.8"),
    (("stops:", "load: heavy\nstops:"), 3, "load must be a finite number"),
])
def test_a_bad_timetable_is_one_line_naming_file_and_line(tmp_path, change, line, message):
    path = files(tmp_path, TIMETABLE.replace(*change))
    with pytest.raises(ScenarioError) as failure:
        load_timetable(path)
    text = str(failure.value)
    assert text.startswith(f"{path} line {line}: ") and message in text and "\n" not in text


def test_a_missing_line_file_is_one_line(tmp_path):
    path = files(tmp_path, TIMETABLE.replace("line.yaml", "no-such-line.yaml"))
    with pytest.raises(ScenarioError, match="no-such-line.yaml"):
        load_timetable(path)


def test_a_running_time_below_the_minimum_is_refused_at_its_stop(tmp_path):
    timetable = load_timetable(files(tmp_path))
    minimums = check_minimum_times(timetable, METRO)  # 100 s and 170 s are enough
    assert all(0.0 < m < s.running_time for m, s in zip(minimums, timetable.sections,
                                                         strict=True))
    fastest = minimums[0]
    tight = TIMETABLE.replace("arrival: 200, departure: 230",
                              f"arrival: {100 + int(fastest)}, departure: 230")
    timetable = load_timetable(files(tmp_path, tight))
    with pytest.raises(ScenarioError) as failure:
        check_minimum_times(timetable, METRO)
    assert str(failure.value).startswith(
        f"{tmp_path / 'timetable.yaml'} line 5: the running time {int(fastest)} s from A to B "
        f"is below its minimum")
    assert "train metro-b at 1 times its mass" in str(failure.value)


def test_a_timetable_planned_for_a_load_is_checked_at_that_load(tmp_path):
    """The running times of a timetable planned for a heavier train are refused below
    that train's minimum, though the nominal train makes them; the minimums returned are
    still the nominal train's, the least a journey's allocation may give it."""
    nominal = check_minimum_times(load_timetable(files(tmp_path)), METRO)
    line = load_line(tmp_path / "line.yaml")
    loaded = minimum_running_time(section_line(line, 0, 1200), METRO, 1.3)
    assert loaded > nominal[0]
    between = (nominal[0] + loaded) / 2
    text = TIMETABLE.replace("arrival: 200, departure: 230",
                             f"arrival: {100 + between:.2f}, departure: 230")
    assert check_minimum_times(load_timetable(files(tmp_path, text)), METRO)[0] == nominal[0]
    with pytest.raises(ScenarioError, match="below its minimum .* at 1.3 times its mass"):
        check_minimum_times(load_timetable(files(tmp_path, "load: 1.3\n" + text)), METRO)
    planned = load_timetable(files(tmp_path, "load: 1.3\n" + TIMETABLE))
    assert planned.load == 1.3 and check_minimum_times(planned, METRO) == nominal


def test_the_minimum_running_time_grows_with_the_grade_and_with_a_weaker_train(tmp_path):
    files(tmp_path)
    flat = minimum_running_time(section_line(load_line(tmp_path / "line.yaml"), 0, 1200),
                                METRO)
    files(tmp_path, grade=25)
    steep = minimum_running_time(section_line(load_line(tmp_path / "line.yaml"), 0, 1200),
                                 METRO)
    weak = minimum_running_time(section_line(load_line(tmp_path / "line.yaml"), 0, 1200),
                                {**METRO, "plant.max_traction_force": 120.0})
    assert flat < steep < weak


def test_a_section_line_is_the_line_seen_from_its_first_stop(tmp_path):
    files(tmp_path)
    line = load_line(tmp_path / "line.yaml")
    section = section_line(line, 1200.0, 3000.0)
    assert section.stop_position == 1800.0
    assert [s.name for s in section.stations] == ["B", "C"]
    assert section.planned_run_time is None
    for x in (-100.0, 0.0, 400.0, 1000.0, 1799.0):  # behind the stop too: the belt's
        assert section.speed_limit(x) == line.speed_limit(x + 1200.0)
        assert section.additional_resistance(x, 100.0) == pytest.approx(
            line.additional_resistance(x + 1200.0, 100.0))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["metro-line", "hsr-journey"])
def test_the_shipped_timetables_add_5_to_10_percent_to_every_loaded_minimum(name):
    """Planned for the crush-laden train (the heaviest robustness.py draws), with the
    supplement real timetables add."""
    timetable = load_timetable(config_dir() / "timetables" / f"{name}.yaml")
    values = complete({"plant.train": timetable.train}, [])
    assert timetable.load == 1.3
    for section in timetable.sections:
        minimum = minimum_running_time(section_line(timetable.line, section.start, section.end),
                                       values, timetable.load)
        assert 1.05 * minimum <= section.running_time <= 1.10 * minimum, section
