"""The independent dynamic programme of the least-energy run, against runs worked by hand."""

import subprocess

import numpy as np
import pytest
from commands import invocation

from ato_nodes.core.config.schema import defaults
from ato_nodes.core.scoring.operation import Regeneration
from ato_nodes.core.train.line import Line, Section, Station
from ato_nodes.core.train.plant import TrainParameters
from ato_nodes.studies import energy_optimum as optimum

LENGTH = 1000.0


def line(limits=((0.0, LENGTH, 40.0),)) -> Line:
    return Line("flat", LENGTH, (), (), (), tuple(Section(*limit) for limit in limits), (),
                (Station("A", 0.0, 0.0), Station("B", LENGTH, 0.0)), None)


# 100 t, no rotating mass, no resistance; 98 kN of traction and of brake at any speed:
# 98 / (100 x 9.8) x 1000 = 100 N/kN, xi = 9.8 / 1000 -> 0.98 m/s^2 either way.
TRAIN = TrainParameters.from_values({
    **defaults(), "plant.mass": 100.0, "plant.gamma": 0.0, "plant.gravity": 9.8,
    "plant.davis_a": 0.0, "plant.davis_b": 0.0, "plant.davis_c": 0.0, "plant.envelope": True,
    "plant.max_traction_force": 98.0, "plant.max_traction_power": 1e6,
    "plant.max_brake_force": 98.0, "plant.max_brake_power": 1e6, "plant.length": 0.0})


def test_without_resistance_the_optimum_is_the_lowest_peak_speed():
    """With no resistance the least energy in a time is the lowest peak speed: full
    traction to v, coasting (at v: nothing slows it), full brake. v = 20 m/s takes
    1000 / 20 + 20 / (2 x 0.98) x 2 = 70.408 s; its kinetic energy 0.5 x 100 t x 20^2 =
    20,000 kJ, drawn through eta 0.9: 22,222 kJ = 6.1728 kWh. Net, all of the braking
    regenerated at 0.9: 20,000 x (1 / 0.9 - 0.9) kJ = 1.1728 kWh."""
    seconds = 1000.0 / 20.0 + 2.0 * 20.0 / (2.0 * 0.98)
    traction = optimum.section_of(line(), TRAIN, 0.9, Regeneration(force=0.0), 10.0, 0.05)
    found = optimum.journey_optimum([traction], seconds)
    assert found.net_kwh == pytest.approx(20000.0 / 0.9 / 3600.0, rel=0.005)
    assert found.traction_kwh == found.net_kwh  # nothing regenerated
    net = optimum.section_of(line(), TRAIN, 0.9, Regeneration(), 10.0, 0.05)
    assert optimum.journey_optimum([net], seconds).net_kwh == pytest.approx(
        20000.0 * (1.0 / 0.9 - 0.9) / 3600.0, rel=0.005)


def test_the_run_keeps_every_limit_and_a_price_shortens_it():
    """A 10 m/s limit over 400-600 m: no boundary speed there above it; a higher price of
    time gives a shorter run at more energy."""
    section = optimum.section_of(line(((0.0, 400.0, 40.0), (400.0, 600.0, 10.0),
                                       (600.0, LENGTH, 40.0))), TRAIN, 0.9,
                                 Regeneration(force=0.0), 20.0, 0.1)
    cheap, dear = optimum.run_at(section, 50.0), optimum.run_at(section, 500.0)
    inside = (cheap.positions >= 400.0) & (cheap.positions <= 600.0)
    assert np.all(cheap.speeds[inside] <= 10.0 + 1e-9)
    assert np.all(dear.speeds[inside] <= 10.0 + 1e-9)
    assert dear.time < cheap.time and dear.net_kwh > cheap.net_kwh
    assert cheap.speeds[0] == 0.0 and cheap.speeds[-1] == 0.0


def test_a_time_below_the_fastest_run_is_refused():
    section = optimum.section_of(line(), TRAIN, 0.9, Regeneration(force=0.0), 20.0, 0.1)
    with pytest.raises(ValueError, match="shorter than the fastest"):
        optimum.journey_optimum([section], 30.0)


@pytest.mark.parametrize("args, expected", [
    (["metro-line", "--grid", "20:0"], "--grid '20:0'"),
    (["--time", "100"], "give a TIMETABLE or --line"),
    (["no-such-timetable"], "no-such-timetable"),
    (["metro-line", "--times", "1,2"], "--times '1,2': 6 running times"),
    (["--like-ato", "seed004-metro-line", "--train", "metro-b"],
     "--like-ato takes the scenario's line and train"),
    (["--like-ato", "seed004-metro-ato"], "--like-ato seed004-metro-ato: not a journey"),
    (["--like-ato", "no-such-scenario"], "no-such-scenario"),
])
def test_bad_input_is_one_line_and_exit_2(args, expected):
    done = subprocess.run([*invocation("energy_optimum.py"), *args], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0]


def journey_energy(*args: str) -> float:
    """The journey's least energy the script prints for its one grid, kWh."""
    done = subprocess.run([*invocation("energy_optimum.py"), *args], capture_output=True,
                          text=True, timeout=600, check=True)
    row = next(line for line in done.stdout.splitlines() if line.startswith("| 40 |"))
    return float(row.split("|")[3])


@pytest.mark.slow
def test_the_ato_s_problem_costs_more_than_the_line_allows():
    common = ["--time", "840", "--grid", "40:0.2"]
    like_ato = journey_energy("--like-ato", "seed004-metro-line", *common)
    as_allowed = journey_energy("metro-line", *common)
    # the same train and time under the curve's margin and planned rates, its departure
    assert like_ato > as_allowed
