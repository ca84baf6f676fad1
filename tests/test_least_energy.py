"""A journey driven for the least energy (profile.journey.driving least_energy,
core/targets/least_energy.py): each section's ato curve kept under the section
programme's least-energy run, on time, for the weighed train too."""

import dataclasses

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.targets import least_energy, served, strategy
from ato_nodes.core.targets.timetable import load_timetable, section_line
from ato_nodes.core.train.plant import TrainParameters
from ato_nodes.results.journeys import score_run

LEAST = {"profile.journey.driving": "least_energy"}


def section_of(values, index: int):
    """(section, its line planned to the timetable's time less the recovery, nominal
    train, table inputs) of the run's timetable."""
    timetable = load_timetable(values["profile.journey.timetable"])
    section = timetable.sections[index]
    own = dataclasses.replace(
        section_line(RunContext(values).line, section.start, section.end),
        planned_run_time=section.running_time - values["profile.journey.recovery"])
    inputs = {name: values[name] for name in served.TABLE_INPUTS}
    return section, own, TrainParameters.from_values(values), inputs


def traction_kwh(curve, train: TrainParameters) -> float:
    """The traction energy of the curve driven exactly by `train` (force = inertia x
    v dv/dx + resistance, over each cell), kWh before the efficiency."""
    squared = curve.speeds ** 2
    dx = np.diff(curve.positions)
    mean = np.sqrt(0.5 * (squared[1:] + squared[:-1]))
    resistance = np.array([train.resistance(v) for v in mean]) \
        + curve.cells.line_resistance[:-1]
    force = train.mass * ((1.0 + train.gamma) * np.diff(squared) / (2.0 * dx)
                          + train.gravity / 1000.0 * resistance)
    return float(np.sum(np.maximum(force, 0.0) * dx)) / 3600.0


def test_a_section_is_driven_on_time_under_its_least_energy_run_for_less():
    values = prepare("seed004-metro-line", LEAST)
    section, own, train, inputs = section_of(values, 3)
    ceilings = least_energy.ceilings(inputs, own, train)
    assert ceilings[-1] is None  # the cruise curve when no run's curve meets the time
    times = [least_energy.curve_time(inputs, own, train, c) for c in ceilings[:-1]]
    assert len(times) >= 1 and times == sorted(times, reverse=True)  # slowest first
    assert all(t <= own.planned_run_time for t in times)
    curve, said = served.timed_curve(inputs, own, train, section, 0.0, ceilings)
    assert said == [] and not curve.notice
    assert curve.planned_run_time == pytest.approx(own.planned_run_time, abs=0.05)
    ceiling = ceilings[0]
    under = np.sqrt(np.interp(curve.positions, ceiling.positions, np.square(ceiling.speeds)))
    # under the run but where the jerk's rounding passes over a valley of it, by a little
    assert np.all(curve.speeds <= np.maximum(under, inputs["profile.ato.start_speed"]) + 0.05)
    assert np.all(curve.speeds <= curve.limits)
    cruise, _ = served.timed_curve(inputs, own, train, section, 0.0)
    assert cruise.planned_run_time == pytest.approx(own.planned_run_time, abs=0.05)
    assert traction_kwh(curve, train) < 0.95 * traction_kwh(cruise, train)


def test_a_train_weighed_heavier_shares_the_runs_and_stays_on_time(monkeypatch):
    values = prepare("seed004-metro-line", LEAST)
    section, own, nominal, inputs = section_of(values, 1)
    least_energy._runs.cache_clear()
    solved = []
    solve = strategy.solve
    monkeypatch.setattr(strategy, "solve", lambda *a, **k: solved.append(1) or solve(*a, **k))
    ceilings = least_energy.ceilings(inputs, own, nominal)
    made = len(solved)
    heavy = nominal.loaded(1.2, values["plant.davis_absolute"])
    assert least_energy.ceilings(inputs, own, nominal) == ceilings and len(solved) == made
    slowest = served.ato_curve(inputs, own, heavy, ceilings[0])
    assert slowest.notice  # the nominal train's slowest run is too slow for the heavy one
    curve, said = served.timed_curve(inputs, own, heavy, section, 0.0, ceilings)
    assert said == [] and not curve.notice
    assert curve.planned_run_time == pytest.approx(own.planned_run_time, abs=0.05)
    assert curve.planned_run_time < slowest.planned_run_time


def test_a_driving_that_is_not_one_is_refused_in_one_line():
    with pytest.raises(ScenarioError, match="profile.journey.driving must be one of cruise, "
                                            "least_energy"):
        prepare("seed004-metro-line", {"profile.journey.driving": "fastest"})


@pytest.mark.slow
def test_a_least_energy_journey_keeps_its_stations_for_less_traction():
    cruise = prepare("seed004-metro-line", {"profile.journey.driving": "cruise"})
    least = prepare("seed004-metro-line", LEAST)
    scores = [score_run(simulate(values), values) for values in (cruise, least)]
    for score in scores:
        assert score["journey"]["verdict"] == "pass", score["journey"]["summary"]
    assert scores[1]["traction_energy_kwh"] < 0.95 * scores[0]["traction_energy_kwh"]
    python = simulate(least, compiled=False)
    compiled = simulate(least)
    for name in ("speed", "target", "command", "position"):
        assert np.array_equal(python[name], compiled[name]), name


@pytest.mark.slow
def test_a_least_energy_section_keeps_its_passing_window_for_less():
    """St Gallen - Wil's km 12.5 (480-540 s): the slowest run whose curve at its fastest
    passes it in time, capped after it to arrive on time."""
    values = prepare("stgallen-wil-journey", LEAST)
    section, own, train, inputs = section_of(values, 0)
    point = section.passing[0]
    curve, said = served.timed_curve(inputs, own, train, section, 0.0,
                                     least_energy.ceilings(inputs, own, train))
    low, high = served.passing_window(point, 0.0, values["profile.journey.recovery"])
    assert said == [] and low <= curve.passing_time(point.position - section.start) \
        <= high + served.CAP_TOLERANCE
    assert curve.planned_run_time == pytest.approx(own.planned_run_time, abs=0.05)
    cruise, _ = served.timed_curve(inputs, own, train, section, 0.0)
    assert traction_kwh(curve, train) < 0.95 * traction_kwh(cruise, train)
