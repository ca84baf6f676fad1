"""Energy allocation over a journey (core/targets/journey.py): every section at the same
marginal energy, the timetable's total kept, no section below its minimum; scripts/
plan_journey.py's bad input."""

import itertools
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ato_nodes.core.config.scenario import complete
from ato_nodes.core.scoring.operation import Regeneration
from ato_nodes.core.targets import journey
from ato_nodes.core.targets.timetable import check_minimum_times, load_timetable, section_line
from ato_nodes.core.train.lines import for_train
from ato_nodes.studies import energy_optimum as optimum
from test_timetable import LINE

ROOT = Path(__file__).resolve().parents[1]
METRO = complete({"plant.train": "metro-b"}, [])


def curve(scale: float, shortest: float, times: np.ndarray) -> journey.EnergyCurve:
    """A convex energy curve E = scale / (T - shortest + 10) sampled at `times`."""
    return journey.lower_hull([(t, scale / (t - shortest + 10.0)) for t in times])


def test_the_hull_drops_points_above_it_and_ends_at_the_least_energy():
    hull = journey.lower_hull([(100.0, 10.0), (101.0, 9.9), (102.0, 7.0), (104.0, 6.0),
                               (106.0, 5.5), (108.0, 5.6)])
    assert hull.times.tolist() == [100.0, 102.0, 104.0, 106.0]  # 101 s lies above the chord
    assert np.all(np.diff(hull.marginal()) > 0)  # convex: the saving per second shrinks


def test_the_allocation_equalises_the_marginal_energy_and_keeps_the_total():
    times = np.linspace(100.0, 200.0, 2001)
    curves = [curve(2000.0, 100.0, times), curve(8000.0, 100.0, times)]
    allocation = journey.allocate(curves, [100.0, 100.0], 240.0)
    assert sum(allocation.times) == pytest.approx(240.0)
    slopes = [-scale / (t - 90.0) ** 2 * 3600.0
              for scale, t in zip((2000.0, 8000.0), allocation.times, strict=True)]
    assert slopes == pytest.approx([allocation.marginal] * 2, rel=0.01)
    # dE/dT equal: (T2 - 90) / (T1 - 90) = sqrt(8000 / 2000) = 2
    assert allocation.times[1] - 90.0 == pytest.approx(2 * (allocation.times[0] - 90.0),
                                                       rel=0.01)


def test_the_allocation_keeps_each_section_at_its_least_time_and_refuses_too_little():
    times = np.linspace(100.0, 200.0, 201)
    curves = [curve(1.0, 100.0, times), curve(9000.0, 100.0, times)]
    allocation = journey.allocate(curves, [120.0, 100.0], 240.0)
    assert allocation.times[0] == pytest.approx(120.0)  # its saving is too small to buy time
    assert sum(allocation.times) == pytest.approx(240.0)
    with pytest.raises(ValueError, match="shorter than its sections can be run"):
        journey.allocate(curves, [120.0, 130.0], 240.0)


def test_the_best_split_is_the_best_of_every_combination():
    random = np.random.default_rng(5)
    runs = [sorted(zip(100 + 40 * random.random(6), 10 + 30 * random.random(6),
                       strict=True)) for _ in range(3)]
    total = 370.0
    feasible = [c for c in itertools.product(*runs) if sum(t for t, _ in c) <= total - 0.3]
    brute = min(sum(e for _, e in c) for c in feasible)
    times, energy = journey.best_split(runs, total)
    assert energy <= brute + 1e-9 and sum(times) <= total
    assert energy == pytest.approx(min(sum(e for _, e in c) for c in itertools.product(*runs)
                                       if sum(t for t, _ in c) <= total))


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    """A two-section metro journey, a flat and a steep section, timed at the minimum + 8 %,
    planned."""
    folder = tmp_path_factory.mktemp("journey")
    (folder / "line.yaml").write_text(LINE.replace("GRADE", "20"))
    stops = "stops:\n  - {station: A, departure: 0}\n  - {station: B, arrival: T1, " \
            "departure: D1}\n  - {station: C, arrival: T2}\n"
    path = folder / "timetable.yaml"
    path.write_text("line: line.yaml\ntrain: metro-b\n" + stops.replace("T1", "999").replace(
        "D1", "1030").replace("T2", "2000"))
    minimums = check_minimum_times(load_timetable(path), METRO)
    first, second = (math.ceil(1.08 * m) for m in minimums)
    path.write_text("line: line.yaml\ntrain: metro-b\n" + stops.replace("T1", str(first))
                    .replace("D1", str(first + 30)).replace("T2", str(first + 30 + second)))
    timetable = load_timetable(path)
    plan = journey.plan_journey(timetable, METRO, check_minimum_times(timetable, METRO))
    return timetable, plan


@pytest.mark.slow
def test_a_planned_journey_keeps_the_timetable_total_and_every_minimum(toy):
    timetable, plan = toy
    assert sum(plan.allocation.times) == pytest.approx(timetable.running_time)
    assert all(t >= m for t, m in zip(plan.allocation.times, plan.minimums, strict=True))
    for run, section, t in zip(plan.driven, plan.sections, plan.allocation.times, strict=True):
        assert t - 3.0 < journey.point(run, section)[0] <= t + 1e-6  # on time, hardly early


def test_a_planned_journey_has_one_marginal_energy_on_its_curves(toy):
    _, plan = toy
    for runs, t, least in zip(plan.runs, plan.allocation.times, plan.minimums, strict=True):
        hull = journey.lower_hull(runs)
        if t <= max(least, hull.times[0]) + 1e-9:
            continue  # at its least time: its marginal may be flatter
        slopes = hull.marginal()
        k = int(np.searchsorted(hull.times, t)) - 1  # the segment it ends on
        before, after = slopes[max(k - 1, 0)], slopes[min(k + 1, len(slopes) - 1)]
        assert before - 1e-6 <= plan.allocation.marginal <= after + 1e-6


def test_a_planned_journey_beats_the_uniform_split_and_is_near_the_best(toy):
    timetable, plan = toy
    comparison = journey.compare(plan, timetable.running_time)
    uniform = sum(run.energy_kwh for run in comparison.uniform_runs)
    assert sum(comparison.uniform_times) == pytest.approx(timetable.running_time)
    assert comparison.best_energy_kwh <= plan.energy_kwh <= uniform
    assert plan.energy_kwh <= 1.03 * comparison.best_energy_kwh
    assert sum(comparison.best_times) <= timetable.running_time


@pytest.mark.slow
@pytest.mark.parametrize("index, running_time", [(0, 131.8), (2, 134.7)])
def test_a_section_run_is_within_a_percent_of_the_independent_optimum(index, running_time):
    """metro-line's Westgate-Market and Riverside-Central (a limit rising behind the train,
    a stop braked along its curve) driven by the section programme, against the
    independent programme (studies/energy_optimum.py, 20 m, 0.05 m/s) on the same problem
    (the margin under the limits, the departure time added) at the run's own time: at most
    1 % more traction energy (without the landing control 1.8 % and 2.2 %)."""
    timetable = load_timetable(ROOT / "msg_config" / "timetables" / "metro-line.yaml")
    values = complete({"plant.train": timetable.train}, [])
    problem = journey.section_problems(timetable, values)[index]
    run = problem.driven(running_time)
    section = problem.section
    check = optimum.section_of(section_line(for_train(timetable.line, values), section.start,
                                            section.end),
                               problem.problem.train, values["plant.efficiency"],
                               Regeneration(force=0.0), 20.0, 0.05, values["profile.ato.margin"])
    best = optimum.journey_optimum([check], run.time).traction_kwh
    assert running_time - 1.0 < journey.point(run, problem)[0] <= running_time
    assert run.energy_kwh <= 1.01 * best


def script(*args):
    return subprocess.run([sys.executable, str(ROOT / "scripts" / "plan_journey.py"),
                           *map(str, args)], capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("args, words", [
    (["no-such-line"], ["unknown line 'no-such-line'"]),
    (["metro-line", "--train", "nonexistent"], ["unknown train 'nonexistent'"]),
    (["metro-line", "--train", "crh5"], ["is below its minimum", "train crh5"]),
    (["metro-interstation", "--timetable", ROOT / "msg_config/timetables/metro-line.yaml"],
     ["is for line", "not metro-interstation"]),
    (["metro-interstation"], ["cannot read timetable file"]),
])
def test_plan_journey_refuses_bad_input_in_one_line(args, words):
    result = script(*args)
    assert result.returncode == 2 and result.stdout == ""
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    for word in words:
        assert word in result.stderr
