"""A temporary speed restriction on a journey (profile.journey.speed_restriction,
core/targets/restriction.py): the line's limits lowered on its stretch, the restricted
section's curves under it, the notice of a running time it makes unmet, the late
arrival caught up after it (compiled as in Python), the recorded limit the scorer
judges overspeed against (in-process and in the stack's bag), a journey without one
unchanged, bad input in one line."""

import re
import subprocess

import numpy as np
import pytest

from ato_nodes.bags.bagio import read_run
from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, prepare
from ato_nodes.core.config.schema import defaults
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.core.targets.restriction import NAME
from ato_nodes.core.targets.served import replans, section_table
from ato_nodes.core.targets.timetable import load_timetable
from ato_nodes.core.train.line import Section, with_speed_restrictions
from commands import ROOT, invocation, run_stack

SCENARIO = "seed004-metro-line"
START, END, SPEED = 4000.0, 4600.0, 8.33  # 30 km/h between Riverside and Central
RESTRICTION = f"{NAME}={START:g}:{END:g}:{SPEED:g}"


def metro(*overrides):
    return apply_overrides(load_scenario(SCENARIO), list(overrides))


@pytest.fixture(scope="module")
def timetable():
    return load_timetable(metro()["profile.journey.timetable"])


@pytest.fixture(scope="module")
def restricted():
    return RunContext(metro(RESTRICTION)).plan


def test_restrictions_lower_the_lines_limits_on_their_stretches_only(timetable):
    line = timetable.line
    restrictions = (Section(START, END, SPEED),
                    Section(4300.0, 5000.0, 12.0),   # overlapping the first: the lower applies
                    Section(3500.0, 4100.0, 20.0))   # over three limits, one of them lower
    lowered = with_speed_restrictions(line, restrictions)
    limits = lowered.speed_limits
    assert limits[0].start == 0.0 and limits[-1].end == line.length
    assert all(a.end == b.start for a, b in zip(limits, limits[1:], strict=False))  # no gaps
    assert len(limits) > len(line.speed_limits)
    for position in np.arange(0.0, line.length, 10.0):  # every restriction's ends among them
        expected = min([line.speed_limit(position)] + [
            restriction.value for restriction in restrictions
            if restriction.start <= position < restriction.end])
        assert lowered.speed_limit(position) == expected, position
    assert lowered.speed_limit(3700.0) == line.speed_limit(3700.0) < 20.0  # kept: lower
    assert with_speed_restrictions(line, ()) == line


def test_the_restricted_section_is_planned_under_it_and_said_at_start_up(restricted,
                                                                        timetable):
    unrestricted = RunContext(metro()).plan
    assert unrestricted.notice is None
    riverside, central = timetable.stops[2:4]
    assert restricted.notice.count("\n") == 0
    assert restricted.notice.startswith(f"{riverside.station} - {central.station}: ")
    assert "cannot be met" in restricted.notice and "minimum-time" in restricted.notice
    journey, length = restricted.journey, metro()["plant.length"]
    section = 2
    assert journey.times[section, 0] > central.arrival - riverside.departure
    for level in range(journey.levels):
        grid = section_table(journey, section, level).grid
        along = grid[0] + riverside.position
        inside = (along >= START) & (along < END + length)  # until the tail is past it
        assert np.all(grid[1][inside] <= SPEED) and np.all(grid[2][inside] == SPEED)
        assert np.all(grid[2][~inside] > SPEED)
    for other in (0, 1, 3, 4, 5):  # the other sections' curves are the unrestricted ones
        for level in range(journey.levels):
            assert np.array_equal(section_table(journey, other, level).grid,
                                  section_table(unrestricted.journey, other, level).grid)
    assert restricted.limit(START + 1.0) == SPEED and restricted.limit(START - 1.0) > SPEED


def test_two_sections_made_late_are_said_in_one_line(timetable):
    plan = RunContext(metro(f"{RESTRICTION},8500:9000:8.33")).plan
    notices = plan.notice.split(" | ")
    assert "\n" not in plan.notice and len(notices) == 2
    for notice, (origin, destination) in zip(notices, ((2, 3), (4, 5)), strict=True):
        stops = timetable.stops
        assert notice.startswith(f"{stops[origin].station} - {stops[destination].station}: ")


def arrival(run, mark):
    """When the train first stood within the berth of `mark`, s."""
    standing = (np.abs(run["position"] - mark) < 1.0) & (run["speed"] < 0.01)
    return run["t"][np.argmax(standing)]


@pytest.mark.slow
def test_the_late_arrival_is_caught_up_after_it_compiled_as_in_python(timetable):
    held = "profile.journey.dwell_extension=3:10"  # leaving Riverside late: a re-plan there
    central, university = timetable.stops[3:5]
    reached = f"run.duration={university.arrival + 75:g}"  # at University, kept late too
    values = metro(RESTRICTION, held, reached)
    compiled, python = simulate(values), simulate(values, compiled=False)
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name
    late = arrival(python, central.position) - central.arrival
    assert late > 30.0
    made = replans(RunContext(values).plan, values["run.period"], python["position"])
    (replan,) = [replan for replan in made if replan.origin == central.station]
    (through,) = [replan for replan in made if replan.destination == central.station]
    said = float(re.search(r"([\d.]+) s late at ", through.text()).group(1))
    assert through.minimum_time and said == pytest.approx(late, abs=3.0)  # not the curve's
    dwell = {station.name: station.dwell for station in timetable.line.stations}[central.station]
    assert replan.lateness == pytest.approx(central.arrival + late + dwell - central.departure,
                                            abs=2 * values["run.period"])  # travel / step
    assert replan.running_time < replan.on_time - 1.0
    kept = simulate(metro(RESTRICTION, held, reached, "profile.journey.catch_up=0"))
    late_kept, caught = (arrival(run, university.position) - university.arrival
                         for run in (kept, python))
    assert caught < late_kept - 1.0


@pytest.mark.slow
def test_the_recorded_and_scored_limit_is_the_restricted_one(timetable):
    values, plain = metro(RESTRICTION, "run.duration=460"), metro("run.duration=460")
    series = simulate(values)
    inside = (series["position"] >= START) & (series["position"] < END)
    assert np.any(inside) and np.all(series["speed_limit"][inside] == SPEED)
    assert np.all(series["speed"][inside] <= SPEED)
    assert score_series(series, values)["overspeed_time"] == 0.0
    unrestricted = simulate(plain)  # what the restriction keeps the train from
    assert np.max(unrestricted["speed"][(unrestricted["position"] >= START)
                                        & (unrestricted["position"] < END)]) > SPEED
    over = dict(series, speed=np.where(inside, SPEED + 0.5, series["speed"]))
    assert score_series(over, values)["overspeed_time"] > 0.0  # judged against SPEED,
    assert SPEED + 0.5 < timetable.line.speed_limit(START)     # not the line's limit


def test_a_journey_without_one_keeps_its_bits_and_one_keeps_them_until_it(timetable):
    default = f"{NAME}={defaults()[NAME]}"
    plain, said = (simulate(metro("run.duration=420", *extra)) for extra in ((), (default,)))
    for name in plain:
        assert np.array_equal(plain[name], said[name], equal_nan=True), name
    restricted = simulate(metro(RESTRICTION, "run.duration=420"))
    riverside = timetable.stops[2]
    before = plain["t"] < riverside.arrival  # its horizon sees the next curve at the stop
    for name in plain:
        assert np.array_equal(plain[name][before], restricted[name][before],
                              equal_nan=True), name
    assert not np.array_equal(plain["speed"], restricted["speed"])


@pytest.mark.integration
def test_the_stack_records_the_restricted_limit_as_in_process(tmp_path):
    overrides = [RESTRICTION, "run.duration=440"]
    bag = tmp_path / "bag"
    run_stack(SCENARIO, bag, overrides)
    run, values = read_run(bag), prepare(SCENARIO, overrides)
    series = simulate(values)
    for name in ("position", "speed", "target", "command", "speed_limit"):
        assert np.array_equal(run.series[name], series[name]), name
    inside = (run.series["position"] >= START) & (run.series["position"] < END)
    assert np.any(inside) and np.all(run.series["speed_limit"][inside] == SPEED)
    assert score_series(run.series, run.parameters)["overspeed_time"] == 0.0


@pytest.mark.parametrize("restriction,message", [
    ("4000:4600", "must be START:END:SPEED"),
    ("4000:4600:8.33,", "must be START:END:SPEED"),
    ("4000:4600:-8", "must be START:END:SPEED"),
    ("4600:4000:8.33", "its start 4600 m is not before its end 4000 m"),
    ("4000:4000:8.33", "is not before its end"),
    ("11000:12000:8.33", "11000-12000 m is off the line (0-11400 m)"),
    ("4000:4600:0", "0 m/s is not above profile.ato.margin"),
    ("4000:4600:22.22", "lowers no limit: the line's on 4000-4600 m are at most 22.22 m/s"),
    ("3600:3900:17", "lowers no limit"),
])
def test_bad_input_is_one_line(restriction, message):
    with pytest.raises(ScenarioError, match=re.escape(message)) as error:
        _ = RunContext(metro(f"{NAME}={restriction}")).plan
    assert "\n" not in str(error.value)


@pytest.mark.slow
def test_the_delay_study_refuses_a_restriction_off_the_line_in_one_line():
    done = subprocess.run([*invocation("journey_delay.py"), SCENARIO,
                           "--restriction", "11000:12000:8"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "is off the line" in done.stderr


def test_the_delay_study_wants_a_delay_or_a_restriction():
    done = subprocess.run([*invocation("journey_delay.py"), SCENARIO],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "--restriction" in done.stderr
