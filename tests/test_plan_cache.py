"""The process's caches of plans (core/config/context.py PLAN_CACHES): a run's plan is
built once for its validation and simulation together, a journey's tables are built anew
for any input they are built from and shared for the same inputs."""

import dataclasses
import hashlib

import numpy as np
import pytest

from ato_nodes.core.config.context import RunContext, forget_plans
from ato_nodes.core.config.scenario import apply_overrides, prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.targets import profiles, served
from ato_nodes.core.targets.timetable import load_timetable


def test_prepare_and_simulate_build_a_journeys_tables_once(monkeypatch):
    built = []
    build = served.new_journey_table
    monkeypatch.setattr(served, "new_journey_table",
                        lambda *arguments: built.append(1) or build(*arguments))
    forget_plans()
    values = prepare("seed004-metro-line", {"plant.mass_factor": 1.013})
    simulate(apply_overrides(values, {"run.duration": 1.0}))
    assert len(built) == 1


def test_prepare_and_simulate_build_an_ato_curve_once():
    forget_plans()
    values = prepare("seed004-metro-ato", {"plant.mass_factor": 1.013})
    simulate(apply_overrides(values, {"run.duration": 1.0}))
    assert profiles._ato_curve.cache_info().misses == 1


def digest(table: served.JourneyTable) -> str:
    """The sha256 of every field of a journey's tables."""
    text = hashlib.sha256()
    for value in table:
        text.update(np.ascontiguousarray(value).tobytes() if isinstance(value, np.ndarray)
                    else repr(value).encode())
    return text.hexdigest()


CHANGED_VALUES = {
    "profile.ato.acceleration": 0.7, "profile.ato.deceleration": 0.6, "profile.ato.margin": 0.6,
    "profile.ato.stop_jerk": 0.25, "profile.ato.start_speed": 0.4,
    "profile.journey.recovery": 3.0, "profile.journey.catch_up": 2,
    "profile.journey.catch_up_share": 0.97, "profile.journey.catch_up_braking": 1.1,
    "profile.journey.catch_up_after": 2.0, "profile.journey.berth": 0.5,
    "profile.journey.dwell_extension": "2:5", "profile.journey.speed_restriction": "100:400:10",
    "profile.envelope_share": 0.9, "profile.jerk": 0.5, "profile.departure_jerk": 0.5,
    "plant.length": 60.0,
}


@pytest.fixture(scope="module")
def journey():
    """seed004-metro-line's inputs with one faster curve per section (quicker to build)."""
    values = apply_overrides(prepare("seed004-metro-line"), {"profile.journey.catch_up": 1})
    context = RunContext(values)
    return load_timetable(values["profile.journey.timetable"]), values, context.line, \
        context.train


@pytest.mark.parametrize("name", sorted(CHANGED_VALUES))
def test_a_journey_for_a_changed_value_is_built_anew(journey, name):
    timetable, values, line, train = journey
    assert name in served.TABLE_INPUTS and values[name] != CHANGED_VALUES[name]
    changed = {**values, name: CHANGED_VALUES[name]}  # not validated: that would build it
    expect_new_then_shared(journey, (timetable, changed, line, train))


def test_a_journey_for_another_train_line_or_timetable_is_built_anew(journey):
    timetable, values, line, train = journey
    heavier = dataclasses.replace(train, mass=1.1 * train.mass)
    last = line.speed_limits[-1]
    limits = (*line.speed_limits[:-1], dataclasses.replace(last, value=last.value - 1.0))
    slower = dataclasses.replace(line, speed_limits=limits)
    stops = list(timetable.stops)
    stops[-1] = dataclasses.replace(stops[-1], arrival=stops[-1].arrival + 5.0)
    later = dataclasses.replace(timetable, stops=tuple(stops))
    for inputs in ((timetable, values, line, heavier), (timetable, values, slower, train),
                   (later, values, line, train)):
        expect_new_then_shared(journey, inputs)


def expect_new_then_shared(base, inputs) -> None:
    """The tables of `inputs` differ from those of `base` (built, or read from the cache),
    are built once for them, and then read from the cache."""
    first = served.journey_table(*base)[0]
    misses = served._journey_tables.cache_info().misses
    table = served.journey_table(*inputs)
    assert served._journey_tables.cache_info().misses == misses + 1
    assert digest(table[0]) != digest(first)
    hits = served._journey_tables.cache_info().hits
    assert served.journey_table(*inputs) is table
    assert served._journey_tables.cache_info().hits == hits + 1
    assert served.journey_table(*base)[0] is first  # the base's still kept
