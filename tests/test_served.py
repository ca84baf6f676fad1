"""The journey as the target (core/targets/served.py): each section's curve, the hold at
each stop until its departure (or a late train's arrival plus the dwell), the state the
profile derives, the horizon over a departure, bad input in one line."""

import math

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.stages import ProfileStage
from ato_nodes.core.config.schema import NodeValues
from ato_nodes.core.targets.served import JourneyState, departure, journey_speed, observed
from ato_nodes.core.targets.timetable import load_timetable

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
    start = plan.speed(0.0, 0.0)
    assert start == metro()["profile.ato.start_speed"]
    assert plan.speed(0.0, market.position - 500.0) > 10.0
    assert plan.speed(0.0, market.position) == 0.0  # the curve stops at the mark
    on_time = JourneyState(0, market.arrival - 3.0)
    assert departure(journey, on_time) == market.departure
    assert journey_speed(journey, on_time, market.departure - 0.01, market.position) == 0.0
    assert journey_speed(journey, on_time, market.departure, market.position) == start
    dwell = {s.name: s.dwell for s in timetable.line.stations}[market.station]
    late = JourneyState(0, market.departure - 5.0)  # the station's dwell from its arrival
    assert departure(journey, late) == market.departure - 5.0 + dwell
    assert journey_speed(journey, late, market.departure + 1.0, market.position) == 0.0
    assert journey_speed(journey, late, departure(journey, late), market.position) == start
    last = JourneyState(len(timetable.sections) - 1, 900.0)
    assert journey_speed(journey, last, 1e6, timetable.stops[-1].position) == 0.0


def test_the_state_follows_the_position_and_time(plan, timetable):
    journey, mark = plan.journey, timetable.stops[1].position
    running = JourneyState(0, math.nan)
    berth = journey.berth
    assert observed(journey, running, 100.0, mark - 0.05, 0.5) == running  # still moving
    assert observed(journey, running, 100.0, mark - 2 * berth, 0.0) == running  # short
    assert observed(journey, running, 100.0, mark - 0.05, 0.0) == JourneyState(0, 100.0)
    assert observed(journey, running, 100.0, mark + 0.05, 0.0) == JourneyState(0, 100.0)
    standing = JourneyState(0, 100.0)
    leaving = timetable.stops[1].departure
    assert observed(journey, standing, leaving - 0.1, mark, 0.0) == standing
    after = observed(journey, standing, leaving, mark, 0.0)  # the next section, running
    assert after.section == 1 and math.isnan(after.arrival)


def test_the_horizon_shows_the_departure_as_it_will_happen(timetable):
    market = timetable.stops[1]
    values = metro("controller.preview=30")
    stage = ProfileStage(NodeValues("profile", values))
    stage.context.plan.state = JourneyState(0, market.arrival)
    period = values["run.period"]
    step = round(market.departure / period) - 10  # 1 s before the departure
    horizon = stage.context.horizon(step, market.position, 30)
    times = (step + np.arange(31)) * period
    held = times < market.departure
    assert np.all(np.array(horizon)[held] == 0.0)
    leaving = int(np.argmin(held))  # the first entry at the departure: the train starts
    assert values["profile.ato.start_speed"] <= horizon[leaving] < 0.2
    assert np.all(np.diff(horizon[leaving:]) > 0.0)


def test_a_run_stops_at_each_mark_and_leaves_at_its_departure(timetable):
    values = metro("run.duration=320")
    run = simulate(values)
    t, position, target = run["t"], run["position"], run["target"]
    for stop in timetable.stops[1:3]:
        held = np.flatnonzero((np.abs(position - stop.position) < 1.0) & (target == 0.0))
        assert abs(position[held[-1]] - stop.position) < 0.1
        assert np.all(run["speed"][held[10:]] == 0.0)  # standing while held
        arrived = t[held[0]]
        assert t[held[-1]] + values["run.period"] == pytest.approx(
            max(stop.departure, arrived + 25.0), abs=0.5)


def late_timetable(tmp_path):
    """The metro's first two stops, the first section far too fast for the train."""
    path = tmp_path / "late.yaml"
    path.write_text("line: lines/metro-line.yaml\ntrain: metro-b\nstops:\n"
                    "  - {station: Westgate (synthetic), departure: 0}\n"
                    "  - {station: Market (synthetic), arrival: 100, departure: 125}\n"
                    "  - {station: Riverside (synthetic), arrival: 250}\n")
    return str(path)


def test_a_late_train_leaves_its_dwell_after_it_arrived_compiled_as_in_python(tmp_path):
    values = metro(f"profile.journey.timetable={late_timetable(tmp_path)}",
                   "run.duration=170")
    plan = RunContext(values).plan
    assert "Westgate (synthetic) - Market (synthetic)" in plan.notice
    compiled, python = simulate(values), simulate(values, compiled=False)
    for name in python:
        assert np.array_equal(compiled[name], python[name], equal_nan=True), name
    t, position, target = python["t"], python["position"], python["target"]
    held = np.flatnonzero((np.abs(position - 1550.0) < 1.0) & (target == 0.0))
    arrived, left = t[held[0]], t[held[-1]] + values["run.period"]
    assert arrived > 125.0 - 25.0  # late: after its departure less the dwell
    assert left == pytest.approx(arrived + 25.0, abs=0.5)


@pytest.mark.parametrize("override,message", [
    ("profile.journey.timetable=", "profile.journey.timetable is empty"),
    ("profile.journey.timetable=timetables/hsr-journey.yaml", "is of line"),
    ("plant.initial_position=100", "plant.initial_position is 100"),
])
def test_bad_input_is_one_line(override, message):
    with pytest.raises(ScenarioError, match=message) as error:
        _ = RunContext(metro(override)).plan
    assert "\n" not in str(error.value)
