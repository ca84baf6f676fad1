"""The departure ramp (profile.departure_jerk): a target the standing train can follow."""

import math

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.targets.profiles import DepartureRamp, departing

RAMP = DepartureRamp(delay=1.0, rise=math.sqrt(6.0 * 0.1 / 0.6), speed=0.1)


def test_the_ramp_holds_zero_through_the_delay_and_reaches_the_start_speed_within_the_jerk():
    h = 1e-3
    times = np.arange(0.0, 4.0, h)
    ramp = np.array([departing(RAMP, t, 5.0) for t in times])
    assert not ramp[times < RAMP.delay].any()
    assert np.all(np.diff(ramp) >= 0.0)
    ends = times >= RAMP.delay + RAMP.rise
    assert np.all(ramp[ends] == 5.0)  # past the ramp: the plan's own target
    rising = ramp[(times >= RAMP.delay) & ~ends]
    assert rising.max() < RAMP.speed + 1e-12
    jerk = np.diff(rising, 2) / h ** 2  # d2v/dt2
    assert np.abs(jerk).max() < 0.6 * 1.01  # the smoothstep's peak: profile.departure_jerk


def test_the_ramp_never_raises_the_plans_target():
    assert departing(RAMP, RAMP.delay + 0.9 * RAMP.rise, 0.02) == 0.02


def run_start(scenario, jerk, seconds=20.0):
    values = prepare(scenario, {"profile.departure_jerk": jerk, "run.duration": seconds})
    series = simulate(values)
    return series, values


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["seed004-metro-ato", "seed004-metro-line"])
def test_the_standing_train_follows_its_departure_target(scenario):
    stepped, _ = run_start(scenario, 0.0)
    ramped, values = run_start(scenario, 0.6)
    start = values["profile.ato.start_speed"]
    assert stepped["target"][0] == start and ramped["target"][0] == 0.0
    error = np.abs(ramped["target"] - ramped["speed"])
    # the step asks the standing train for the start speed at once (on the located position
    # a hair more: the curve from a few cm on); the ramp never does
    stepped_error = np.abs(stepped["target"] - stepped["speed"]).max()
    assert error.max() < start <= stepped_error < start + 1e-3
    delay = values["plant.dead_time"] + values["plant.actuator_lag"]
    assert not ramped["target"][ramped["t"] < delay - 1e-9].any()


def test_a_journey_ramps_each_departure_from_its_stop():
    values = prepare("seed004-metro-line", {"profile.departure_jerk": 0.6})
    series = simulate(values)
    target, t = series["target"], series["t"]
    leaves = np.flatnonzero((target[1:] > 0.0) & (target[:-1] == 0.0)) + 1
    assert len(leaves) >= 3  # the origin and stops after it
    delay = values["plant.dead_time"] + values["plant.actuator_lag"]
    for k in leaves[1:]:  # a stop's first non-zero target: far under the start speed
        assert 0.0 < target[k] < 0.2 * values["profile.ato.start_speed"]
        departed = t[k] - delay  # the ramp's first sample after the departure's delay
        assert np.all(series["speed"][(t >= departed - 1.0) & (t < departed)] < 0.01)


def test_a_time_indexed_plan_refuses_the_ramp_in_one_line():
    with pytest.raises(ScenarioError, match="profile.departure_jerk applies to a position"):
        prepare("seed000", {"profile.departure_jerk": 0.5})
