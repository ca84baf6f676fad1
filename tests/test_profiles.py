"""Target curves: seed 000's eq. 25 and tables."""

import numpy as np
import pytest

from ato_nodes.core.config.context import RunContext
from ato_nodes.core.config.scenario import load_scenario
from ato_nodes.core.targets import curve_passes, profiles
from ato_nodes.core.targets.profiles import StepProfile, TableProfile
from ato_nodes.core.base.units import KMH
from ato_nodes.core.config.schema import defaults


@pytest.fixture
def curve():
    return RunContext(defaults()).plan  # seed 000's eq. 25 with the paper's constants


def test_values_at_the_piece_boundaries(curve):
    assert curve.speed(0.0) == 0.0
    assert curve.speed(600.0) == pytest.approx(350 * KMH, abs=0.002 * KMH)
    assert curve.speed(1200.0) == pytest.approx(200 * KMH, abs=0.02 * KMH)
    assert curve.speed(1800.0) == pytest.approx(350 * KMH, abs=0.002 * KMH)
    assert curve.speed(2280.0) == pytest.approx(0.0, abs=1e-9)
    assert curve.speed(2399.9) == 0.0


@pytest.mark.parametrize("t", [600.0, 1200.0, 1800.0])
def test_continuous_at_the_piece_boundaries(curve, t):
    # Vinc = 368.34 km/h is rounded in the paper: Vinc (1 - e^-3) = 350.0014 km/h, so
    # the curve steps by 0.0014 km/h at 600 s and 1800 s; that is all.
    eps = 1e-9
    assert curve.speed(t - eps) == pytest.approx(curve.speed(t + eps), abs=0.002 * KMH)


def test_cruise_levels_and_shape(curve):
    assert curve.speed(500.0) == pytest.approx(350 * KMH)   # first cruise
    assert curve.speed(1100.0) == pytest.approx(200 * KMH)  # low cruise
    assert curve.speed(1700.0) == pytest.approx(350 * KMH)  # second cruise
    # Steepest acceleration at t = 0: Vinc / 120 s = 0.853 m/s^2
    assert ((curve.speed(0.01) - curve.speed(0.0)) / 0.01
            == pytest.approx(368.34 * KMH / 120, rel=1e-3))
    assert curve.speed(800.0) < curve.speed(700.0)  # decelerating piece


def test_step_profile():
    step = StepProfile(2.0, time=1.0)
    assert step.speed(0.99) == 0.0 and step.speed(1.0) == 2.0


def test_table_profile_by_time_and_position(tmp_path):
    table = tmp_path / "curve.csv"
    table.write_text("position,speed\n0,0\n100,10\n300,10\n")
    profile = TableProfile.from_csv(table)
    assert profile.speed(999.0, position=50.0) == pytest.approx(5.0)
    assert profile.speed(0.0, position=1e6) == 10.0


@pytest.mark.parametrize("text, problem", [
    ("time,speed\n0,0\n0,1\n", "strictly increasing"),
    ("t,v\n0,0\n1,1\n", "header"),
    ("time,speed\n0,0\n1,x\n", "two numbers"),
    ("time,speed\n0,-1\n1,1\n", "non-negative"),
])
def test_bad_tables_are_rejected_with_a_reason(tmp_path, text, problem):
    table = tmp_path / "bad.csv"
    table.write_text(text)
    with pytest.raises(ValueError, match=problem):
        TableProfile.from_csv(table)


@pytest.mark.parametrize("scenario", ["seed004-metro-ato", "hsr-neutral-ato"])
def test_the_feasibility_passes_compiled_or_not_agree_bit_for_bit(scenario):
    """The ATO curve's forward and backward passes (compiled when numba is installed) give
    what the same functions run as Python give, on a real line with its resistance."""
    curve = RunContext(load_scenario(scenario)).plan
    cells, train = curve.cells, curve.cells.train
    x = curve.positions
    results = []
    for forward, backward in ((curve_passes.forward_pass, profiles.backward_pass),
                              (curve_passes.forward_pass_of, profiles._backward_pass)):
        squared = curve.caps ** 2
        squared[0] = curve.start_speed ** 2
        forward(squared, 0, x, cells.powered, cells.line_resistance, train.envelope,
                train.davis_a, train.davis_b, train.davis_c, train.xi, cells.share,
                curve.acceleration, curve.power_speed, curve.start_speed ** 2, True)
        stopping = curve.stopping(x[-1] - x) ** 2
        backward(squared, x, stopping, cells.line_resistance, train.envelope, train.davis_a,
                 train.davis_b, train.davis_c, train.xi, cells.share, curve.deceleration)
        results.append(squared.tobytes())
    assert results[0] == results[1]
    assert np.sqrt(np.frombuffer(results[0])).tobytes() == curve.feasible.tobytes()
