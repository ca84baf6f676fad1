"""Per-station indices of a journey (core/scoring/journey.py) on synthetic runs built
here: trapezoidal speed legs between stations, whose stop positions, arrival and
departure times follow from the construction."""

import math

import numpy as np
import pytest

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.scoring.journey import (FAIL, NOT_JUDGED, NOT_REACHED, PASS, PASSED,
                                            STOPPED, journey_indices)
from ato_nodes.core.scoring.operation import operation_indices
from ato_nodes.core.targets.timetable import Stop, Timetable, load_timetable

DT = 0.1       # s, the samples' period
MASS = 300.0   # t
HOLD = -20.0   # N/kN: the holding brake at a standstill
BRAKE = -30.0  # N/kN
SAMPLE = 1.5 * DT  # a departure is seen at the first sample moving: within a sample


def timetable(*stops) -> Timetable:
    """Stops (station, position m, arrival s, departure s) as a timetable of no line."""
    return Timetable("synthetic", "", None, "synthetic",
                     tuple(Stop(*stop, source_line=1) for stop in stops))


# Four stations; the run's t = 0 is the first departure, 100 s on this clock.
ABCD = timetable(("A", 0.0, None, 100.0), ("B", 1000.0, 200.0, 230.0),
                 ("C", 2200.0, 350.0, 380.0), ("D", 3000.0, 460.0, None))


def stand(seconds):
    return ("stand", seconds)


def drive(metres, seconds, traction=40.0, ramp=20.0):
    """A leg from a standstill to a standstill: `ramp` s accelerating at `traction`
    N/kN, cruising, `ramp` s braking."""
    return ("drive", metres, seconds, traction, ramp)


def build(legs, start=0.0, offsets=()):
    """The series of a run of `legs` from `start` (m); `offsets`: (from s, to s, m/s)
    added to the target over that time (the tracking error)."""
    knots, speeds, forces = [0.0], [0.0], []
    for leg in legs:
        now = knots[-1]
        if leg[0] == "stand":
            knots.append(now + leg[1])
            speeds.append(0.0)
            forces.append(HOLD)
            continue
        _, metres, seconds, traction, ramp = leg
        cruise = metres / (seconds - ramp)  # the trapezoid's area is the leg's length
        knots += [now + ramp, now + seconds - ramp, now + seconds]
        speeds += [cruise, cruise, 0.0]
        forces += [traction, 0.0, BRAKE]
    t = np.arange(round(knots[-1] / DT) + 1) * DT
    speed = np.interp(t, knots, speeds)
    interval = np.clip(np.searchsorted(knots, t + 1e-9, side="right") - 1, 0, len(forces) - 1)
    position = start + np.concatenate(([0.0], np.cumsum((speed[1:] + speed[:-1]) / 2 * DT)))
    target = speed.copy()
    for begin, end, offset in offsets:
        target[(t >= begin) & (t <= end)] += offset
    return {"t": t, "position": position, "speed": speed, "target": target,
            "acceleration": np.gradient(speed, t), "force": np.array(forces)[interval]}


def cut(series, until):
    return {name: values[series["t"] <= until] for name, values in series.items()}


def acceleration_energy(metres, seconds, traction=40.0, ramp=20.0):
    """kWh drawn while accelerating to the cruise: traction force times the distance
    covered in the ramp (half the cruise speed times the ramp), through 0.9."""
    cruise = metres / (seconds - ramp)
    return traction * MASS * 9.8 / 1000.0 * cruise * ramp / 2 / 0.9 / 3600.0


# Leaves A 2 s late; B: +0.05 m, 2 s late, leaves 7 s late; C: 0.3 m short, on time;
# D: +0.02 m, 8 s late. The second section at twice the traction, and tracked 0.4 m/s
# off for a while (the first 0.1 m/s).
LATE_RUN = [stand(2.0), drive(1000.05, 100.0), stand(35.0), drive(1199.65, 113.0, 80.0),
            stand(30.0), drive(800.32, 88.0), stand(10.0)]
OFFSETS = ((50.0, 60.0, 0.1), (180.0, 190.0, 0.4))


def test_three_stops_with_known_errors_and_lateness():
    result = journey_indices(build(LATE_RUN, offsets=OFFSETS), ABCD, MASS)
    a, b, c, d = result.stations
    assert [s.outcome for s in result.stations] == [STOPPED] * 4
    assert [s.station for s in result.stations] == ["A", "B", "C", "D"]
    assert [b.stop_error, c.stop_error, d.stop_error] == pytest.approx([0.05, -0.3, 0.02],
                                                                       abs=1e-6)
    assert [b.arrival_lateness, c.arrival_lateness, d.arrival_lateness] == pytest.approx(
        [2.0, 0.0, 8.0], abs=1e-6)
    assert [a.departure_lateness, b.departure_lateness, c.departure_lateness] == \
        pytest.approx([2.0, 7.0, 0.0], abs=SAMPLE)
    assert b.dwell == pytest.approx(35.0, abs=SAMPLE)
    assert math.isnan(a.arrival) and math.isnan(d.departure) and math.isnan(d.dwell)
    assert [s.verdict for s in result.stations] == ["", PASS, FAIL, FAIL]
    assert "stop error" in c.reason and "arrival" not in c.reason
    assert "arrival" in d.reason and "stop error" not in d.reason
    assert result.worst_stop.station == "C"
    assert result.worst_lateness.station == "D"
    assert result.final_arrival_lateness == pytest.approx(8.0, abs=1e-6)
    assert result.verdict == FAIL


def test_sections_standstill_to_standstill():
    result = journey_indices(build(LATE_RUN, offsets=OFFSETS), ABCD, MASS)
    assert [s.running_time for s in result.sections] == pytest.approx([100.0, 113.0, 88.0],
                                                                      abs=SAMPLE)
    # The timetable's 100, 120 and 80 s.
    assert [s.running_time_error for s in result.sections] == pytest.approx([0.0, -7.0, 8.0],
                                                                            abs=SAMPLE)
    energies = [s.traction_energy_kwh for s in result.sections]
    assert energies == pytest.approx([acceleration_energy(1000.05, 100.0),
                                      acceleration_energy(1199.65, 113.0, 80.0),
                                      acceleration_energy(800.32, 88.0)], rel=0.01)
    # Nothing is drawn at a standstill: the sections hold the run's whole traction energy.
    whole = operation_indices(build(LATE_RUN), MASS)["traction_energy_kwh"]
    assert sum(energies) == pytest.approx(whole, rel=1e-9)
    assert result.traction_energy_kwh == pytest.approx(whole, rel=1e-12)
    assert [s.max_abs_error for s in result.sections] == pytest.approx([0.1, 0.4, 0.0])


ON_TIME = [stand(0.0), drive(1000.0, 100.0), stand(30.0), drive(1200.0, 120.0), stand(30.0),
           drive(800.0, 80.0), stand(10.0)]


def test_a_journey_on_time_and_on_the_marks_passes():
    result = journey_indices(build(ON_TIME), ABCD, MASS)
    assert result.verdict == PASS
    assert abs(result.worst_stop.stop_error) < 1e-6
    assert abs(result.final_arrival_lateness) < 1e-6


def test_a_run_ending_before_the_last_station():
    series = build(ON_TIME)
    result = journey_indices(cut(series, 320.0), ABCD, MASS)  # on the way to D
    d = result.stations[-1]
    assert (d.outcome, d.verdict) == (NOT_REACHED, NOT_JUDGED)
    assert "short of the mark" in d.reason
    assert math.isnan(d.stop_error) and math.isnan(d.arrival_lateness)
    assert [s.verdict for s in result.stations[1:3]] == [PASS, PASS]
    assert math.isnan(result.sections[-1].running_time)
    assert math.isnan(result.sections[-1].traction_energy_kwh)
    assert not math.isnan(result.sections[1].running_time)
    assert math.isnan(result.final_arrival_lateness)
    assert result.verdict == NOT_JUDGED


def test_a_run_ending_in_a_dwell():
    result = journey_indices(cut(build(ON_TIME), 260.0), ABCD, MASS)  # standing at C
    c, d = result.stations[2:]
    assert (c.outcome, c.verdict) == (STOPPED, PASS)
    assert math.isnan(c.departure) and math.isnan(c.dwell)
    assert d.outcome == NOT_REACHED
    assert math.isnan(result.sections[2].running_time)


def test_a_missed_stop_fails_and_the_next_is_still_found():
    run = [stand(0.0), drive(1000.0, 100.0), stand(30.0), drive(2000.1, 200.0), stand(10.0)]
    result = journey_indices(build(run), ABCD, MASS)
    b, c, d = result.stations[1:]
    assert (c.outcome, c.verdict) == (PASSED, FAIL)
    assert math.isnan(c.stop_error) and math.isnan(c.arrival)
    assert (d.outcome, d.stop_error) == (STOPPED, pytest.approx(0.1, abs=1e-6))
    assert b.verdict == PASS
    assert [math.isnan(s.running_time) for s in result.sections] == [False, True, True]
    assert result.verdict == FAIL


def test_a_halt_short_of_the_mark_then_a_creep_stops_at_the_mark():
    # 3 m short at 100 s, 5 s standing, 3.05 m crept in 6 s: doors open at +0.05 m.
    run = [stand(0.0), drive(997.0, 100.0), stand(5.0), drive(3.05, 6.0, 10.0, 2.0),
           stand(30.0), drive(1199.95, 120.0), stand(30.0), drive(800.0, 80.0), stand(10.0)]
    b = journey_indices(build(run), ABCD, MASS).stations[1]
    assert b.stop_error == pytest.approx(0.05, abs=1e-6)
    assert b.arrival_lateness == pytest.approx(11.0, abs=1e-6)
    assert b.dwell == pytest.approx(30.0, abs=SAMPLE)


def test_a_standstill_outside_every_window_is_part_of_its_section():
    # A signal check 400 m before C (20 s standing), then on to C.
    run = [stand(0.0), drive(1000.0, 100.0), stand(30.0), drive(800.0, 60.0), stand(20.0),
           drive(400.0, 40.0), stand(30.0), drive(800.0, 80.0), stand(10.0)]
    result = journey_indices(build(run), ABCD, MASS)
    c = result.stations[2]
    assert (c.outcome, c.arrival_lateness) == (STOPPED, pytest.approx(0.0, abs=1e-6))
    assert result.sections[1].running_time == pytest.approx(120.0, abs=SAMPLE)


def test_nothing_is_required_of_the_origin():
    result = journey_indices(build(ON_TIME, start=-2.0), ABCD, MASS)  # starts 2 m short
    a = result.stations[0]
    assert a.stop_error == pytest.approx(-2.0)
    assert (a.verdict, a.reason) == ("", "")
    assert result.stations[1].stop_error == pytest.approx(-2.0, abs=1e-6)


def test_the_shipped_metro_timetable_run_on_time():
    metro = load_timetable("msg_config/timetables/metro-line.yaml")
    legs = [stand(0.0)]
    for section, stop in zip(metro.sections, metro.stops[1:], strict=True):
        legs += [drive(section.end - section.start, section.running_time),
                 stand(stop.dwell if stop.departure is not None else 10.0)]
    result = journey_indices(build(legs), metro, MASS)
    assert [s.station for s in result.stations] == [s.station for s in metro.stops]
    assert result.verdict == PASS
    assert all(s.running_time_error == pytest.approx(0.0, abs=SAMPLE)
               for s in result.sections)


@pytest.mark.parametrize("change, words", [
    (lambda s: s.pop("force"), "need the series force"),
    (lambda s: s.update(t=s["t"][:-1]), "one nonzero length"),
    (lambda s: [values.resize(0, refcheck=False) for values in s.values()],
     "one nonzero length"),
])
def test_bad_series_are_one_line(change, words):
    series = {name: values.copy() for name, values in build(ON_TIME).items()}
    change(series)
    with pytest.raises(ScenarioError, match=words) as error:
        journey_indices(series, ABCD, MASS)
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("window", [0.0, -1.0, 400.0])
def test_a_window_must_fit_the_shortest_section(window):
    with pytest.raises(ScenarioError, match="shortest section \\(C - D, 800 m\\)"):
        journey_indices(build(ON_TIME), ABCD, MASS, window=window)
