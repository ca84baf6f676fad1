"""The journey as the target (core/targets/served.py): each section's curve, the hold at
each stop until its departure (or a late train's arrival plus the dwell), the state the
profile derives, the horizon over a departure, a late train catching up (the re-plans,
said and recorded through the stack as in-process), bad input in one line."""

import math
import subprocess

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext
from ato_nodes.bags.bagio import read_run
from ato_nodes.core.config.scenario import apply_overrides, load_scenario, prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.stages import ProfileStage
from ato_nodes.core.config.schema import NodeValues
from ato_nodes.core.targets.served import (STANDSTILL, JourneyPlan, JourneyState, Replan,
                                           catch_up_level, departure, journey_speed, observed,
                                           replans)
from ato_nodes.core.targets.timetable import load_timetable
from commands import ROOT, invocation, run_stack

SCENARIO = "seed004-metro-line"


def metro(*overrides):
    return apply_overrides(load_scenario(SCENARIO), list(overrides))


@pytest.fixture(scope="module")
def plan():
    return RunContext(metro()).plan


@pytest.fixture(scope="module")
def timetable():
    return load_timetable(metro()["profile.journey.timetable"])


def test_a_section_is_its_curve_and_a_standing_train_waits_for_its_departure(plan, timetable):
    journey, market = plan.journey, timetable.stops[1]
    ramp = journey.departure  # the target leaves standstill as the train can follow
    assert plan.speed(0.0, 0.0) == 0.0
    start = plan.speed(ramp.delay + ramp.rise, 0.0)
    assert start == metro()["profile.ato.start_speed"]
    assert plan.speed(100.0, market.position - 500.0) > 10.0
    assert plan.speed(100.0, market.position) == 0.0  # the curve stops at the mark
    on_time = JourneyState(0, market.arrival - 3.0, 0, 0.0)
    assert departure(journey, on_time) == market.departure
    assert journey_speed(journey, on_time, market.departure - 0.01, market.position) == 0.0
    assert journey_speed(journey, on_time, market.departure + ramp.delay, market.position) == 0.0
    ramped = market.departure + ramp.delay + ramp.rise
    assert journey_speed(journey, on_time, ramped, market.position) == start
    dwell = {s.name: s.dwell for s in timetable.line.stations}[market.station]
    late = JourneyState(0, market.departure - 5.0, 0, 0.0)  # the dwell from its arrival
    assert departure(journey, late) == market.departure - 5.0 + dwell
    assert journey_speed(journey, late, market.departure + 1.0, market.position) == 0.0
    assert journey_speed(journey, late, departure(journey, late) + ramp.delay + ramp.rise,
                         market.position) == start
    last = JourneyState(len(timetable.sections) - 1, 900.0, 0, 0.0)
    assert journey_speed(journey, last, 1e6, timetable.stops[-1].position) == 0.0


def test_the_state_follows_the_position_and_time(plan, timetable):
    journey, mark = plan.journey, timetable.stops[1].position
    running = JourneyState(0, math.nan, 0, 0.0)
    berth = journey.berth
    assert observed(journey, running, 100.0, mark - 0.05, 0.5) == running  # still moving
    assert observed(journey, running, 100.0, mark - 2 * berth, 0.0) == running  # short
    assert observed(journey, running, 100.0, mark - 0.05, 0.0) == JourneyState(0, 100.0, 0, 0.0)
    assert observed(journey, running, 100.0, mark + 0.05, 0.0) == JourneyState(0, 100.0, 0, 0.0)
    standing = JourneyState(0, 100.0, 0, 0.0)
    leaving = timetable.stops[1].departure
    assert observed(journey, standing, leaving - 0.1, mark, 0.0) == standing
    after = observed(journey, standing, leaving, mark, 0.0)  # the next section, running
    assert after.section == 1 and math.isnan(after.arrival)


def test_the_horizon_shows_the_departure_as_it_will_happen(timetable):
    market = timetable.stops[1]
    values = metro("controller.preview=30")
    stage = ProfileStage(NodeValues("profile", values))
    stage.context.plan.state = JourneyState(0, market.arrival, 0, 0.0)
    period = values["run.period"]
    step = round(market.departure / period) - 10  # 1 s before the departure
    horizon = stage.context.horizon(step, market.position, 30)
    times = (step + np.arange(31)) * period
    held = times < market.departure
    assert np.all(np.array(horizon)[held] == 0.0)
    ramp = stage.context.plan.journey.departure  # 0 through the train's dead time and lag
    starting = times >= market.departure + ramp.delay
    assert np.all(np.array(horizon)[~starting] == 0.0)
    leaving = int(np.argmax(starting))  # then the target rises: the train starts
    assert 0.0 < horizon[leaving + 1] < values["profile.ato.start_speed"]
    assert np.all(np.diff(horizon[leaving + 1:]) > 0.0)


def test_a_run_stops_at_each_mark_and_leaves_at_its_departure(timetable):
    values = metro("run.duration=320")
    run = simulate(values)
    t, position, target = run["t"], run["position"], run["target"]
    delay = RunContext(values).plan.journey.departure.delay  # the target held 0 through it
    for stop in timetable.stops[1:3]:
        held = np.flatnonzero((np.abs(position - stop.position) < 1.0) & (target == 0.0))
        assert abs(position[held[-1]] - stop.position) < 0.1
        assert np.all(run["speed"][held[10:]] == 0.0)  # standing while held
        arrived = t[held[0]]
        assert t[held[-1]] + values["run.period"] == pytest.approx(
            max(stop.departure, arrived + 25.0) + delay, abs=0.5)


def late_timetable(tmp_path):
    """The metro's first two stops, the first section far too fast for the train."""
    path = tmp_path / "late.yaml"
    path.write_text("line: lines/metro-line.yaml\ntrain: metro-b\nstops:\n"
                    "  - {station: Westgate (synthetic), departure: 0}\n"
                    "  - {station: Market (synthetic), arrival: 100, departure: 125}\n"
                    "  - {station: Riverside (synthetic), arrival: 250}\n")
    return str(path)


@pytest.mark.slow
def test_a_late_train_leaves_its_dwell_after_it_arrived_compiled_as_in_python(tmp_path):
    # A run refuses a timetable its train cannot keep (tests/test_hostile_journeys.py); the
    # plan of one, built here past that check, makes the train late at Market.
    values = {**metro("run.duration=170"), "profile.journey.timetable": late_timetable(tmp_path)}
    plan = RunContext(values).plan
    assert "Westgate (synthetic) - Market (synthetic)" in plan.notice
    compiled, python = simulate(values), simulate(values, compiled=False)
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name
    t, position, target = python["t"], python["position"], python["target"]
    # Standing at the mark as the profile sees it (travel over the last step), held at 0:
    # a train that runs a few cm past the mark has a zero target before it stands.
    standing = np.abs(np.diff(position, prepend=position[0])) < STANDSTILL * values["run.period"]
    held = np.flatnonzero((np.abs(position - 1550.0) < 1.0) & (target == 0.0) & standing)
    arrived, left = t[held[0]], t[held[-1]] + values["run.period"]
    assert arrived > 125.0 - 25.0  # late: after its departure less the dwell
    delay = plan.journey.departure.delay  # the target held 0 through it after the release
    assert left == pytest.approx(arrived + 25.0 + delay, abs=0.5)


def test_a_late_train_drives_the_slowest_curve_that_wins_its_lateness_back(plan):
    journey = plan.journey
    assert journey.levels == 1 + metro()["profile.journey.catch_up"]
    assert np.all(np.diff(journey.times, axis=1) <= 0.0)  # each curve at least as fast
    times = journey.times[1]
    assert times[-1] < times[0] - 1.0  # the fastest wins a second and more back
    assert catch_up_level(journey, 1, 0.0) == 0 and catch_up_level(journey, 1, -3.0) == 0
    assert catch_up_level(journey, 1, 0.99 * journey.catch_up_after) == 0
    for level in range(1, journey.levels):
        gain = max(times[0] - times[level], journey.catch_up_after)
        chosen = catch_up_level(journey, 1, gain)
        assert times[chosen] <= times[0] - gain and (chosen == 0 or times[chosen - 1] > times[
            0] - gain)
    assert catch_up_level(journey, 1, 1e3) == journey.levels - 1  # minimum-time


def leaving_late(plan, lateness):
    """The re-plan of a train released from Market `lateness` s after its departure."""
    journey = plan.journey
    extended = journey._replace(extensions=np.array([lateness, *journey.extensions[1:]]))
    fresh = JourneyPlan(extended, plan.notice, plan.stations)
    fresh.state = JourneyState(0, journey.departures[0] - journey.dwells[0] - 10.0, 0,
                               0.0)  # early
    fresh.observe(departure(extended, fresh.state), journey.stops[1], 0.0)
    [made] = fresh.replans
    assert made.lateness == pytest.approx(lateness)
    return made


def test_a_replan_is_minimum_time_only_when_the_fastest_curve_does_not_win_it_all_back(plan):
    times = plan.journey.times[1]
    # the fastest curve is the slowest that wins this back (the next slower does not)
    exact = leaving_late(plan, times[0] - (times[-2] + times[-1]) / 2)
    assert exact.running_time == times[-1] and not exact.minimum_time
    assert "minimum-time" not in exact.text()
    short = leaving_late(plan, times[0] - times[-1] + 1.0)
    assert short.running_time == times[-1] and short.minimum_time
    assert "minimum-time, 1.0 s late" in short.text()


def arrival(run, mark):
    """When the train first stood within the berth of `mark`, s."""
    standing = (np.abs(run["position"] - mark) < 1.0) & (run["speed"] < 0.01)
    return run["t"][np.argmax(standing)]


@pytest.mark.slow
def test_a_delayed_train_catches_up_compiled_as_in_python(timetable):
    delayed = ("profile.journey.dwell_extension=2:30", "run.duration=430")
    values = metro(*delayed)
    compiled, python = simulate(values), simulate(values, compiled=False)
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name
    first, second = replans(RunContext(values).plan, values["run.period"], python["position"])
    market, riverside = timetable.stops[1:3]
    assert first.origin == market.station and first.lateness == 30.0  # it arrived early
    assert first.time == pytest.approx(market.departure + 30.0, abs=values["run.period"])
    assert first.running_time < first.on_time and first.minimum_time
    assert second.origin == riverside.station and second.lateness < first.lateness
    kept = simulate(metro(*delayed, "profile.journey.catch_up=0"))
    late, caught = (arrival(run, riverside.position) - riverside.arrival for run in (kept, python))
    assert late > 25.0 and caught < late - 1.0


@pytest.mark.integration
def test_the_stack_says_and_records_the_replans_the_in_process_run_makes(tmp_path):
    overrides = ["profile.journey.dwell_extension=2:30", "run.duration=330"]
    bag = tmp_path / "bag"
    run_stack(SCENARIO, bag, overrides)
    run, values = read_run(bag), prepare(SCENARIO, overrides)
    series = simulate(values)
    for name in ("position", "speed", "target", "command"):
        assert np.array_equal(run.series[name], series[name]), name
    made = replans(RunContext(values).plan, values["run.period"], series["position"])
    assert made and made[0].lateness == 30.0
    assert [{name: replan[name] for name in Replan._fields} for replan in run.replans] == [
        replan._asdict() for replan in made]
    assert run.replans[0]["step"] == round(made[0].time / values["run.period"])


@pytest.mark.integration
def test_a_replan_at_the_last_step_of_a_run_is_in_its_bag(tmp_path):
    delayed = metro("profile.journey.dwell_extension=2:30", "run.duration=330")
    period = delayed["run.period"]
    first = replans(RunContext(delayed).plan, period, simulate(delayed)["position"])[0]
    overrides = ["profile.journey.dwell_extension=2:30",
                 f"run.duration={(round(first.time / period) + 1) * period!r}"]  # its step last
    bag = tmp_path / "bag"
    run_stack(SCENARIO, bag, overrides)
    values = prepare(SCENARIO, overrides)
    made = replans(RunContext(values).plan, period, simulate(values)["position"])
    assert [replan.time for replan in made] == [first.time]  # made at the run's last step
    assert [{name: replan[name] for name in Replan._fields}
            for replan in read_run(bag).replans] == [first._asdict()]


@pytest.mark.parametrize("override,message", [
    ("profile.journey.timetable=", "profile.journey.timetable is empty"),
    ("profile.journey.timetable=timetables/hsr-journey.yaml", "is of line"),
    ("plant.initial_position=100", "plant.initial_position is 100"),
    ("profile.journey.dwell_extension=1:30", "stop 1 is not a stop between the ends"),
    ("profile.journey.dwell_extension=2:30,7:10", "stop 7 is not a stop between the ends"),
    ("profile.journey.dwell_extension=2", "must be STOP:SECONDS"),
    ("profile.journey.dwell_extension=2:3600.5", "3600.5 s at stop 2 is more than 3600 s"),
    ("profile.journey.dwell_extension=3:10,2:1800,2:1801", "3601 s at stop 2 is more than"),
])
def test_bad_input_is_one_line(override, message):
    with pytest.raises(ScenarioError, match=message) as error:
        _ = RunContext(metro(override)).plan
    assert "\n" not in str(error.value)


@pytest.mark.slow
def test_run_stack_refuses_a_dwell_extension_beyond_an_hour_in_one_line(tmp_path):
    done = subprocess.run([*invocation("run_stack"), "--scenario", SCENARIO, "--out",
                           str(tmp_path / "bag"), "--set=profile.journey.dwell_extension=2:3601"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 2 and not (tmp_path / "bag").exists()
    assert done.stderr.count("\n") == 1 and "is more than 3600 s" in done.stderr


def test_the_delay_study_refuses_a_run_that_is_not_a_journey_first_in_one_line():
    done = subprocess.run([*invocation("journey_delay.py"), "seed004-metro", "--delay", "2:30"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 2 and done.stdout == "" and done.stderr.count("\n") == 1
    assert "seed004-metro is not a journey" in done.stderr


@pytest.mark.slow
def test_the_delay_study_refuses_a_delay_outside_the_journey_in_one_line():
    done = subprocess.run([*invocation("journey_delay.py"), SCENARIO, "--delay", "1:30"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "stop 1 is not a stop between" in done.stderr

