"""Energy allocation over a journey, ROS-free: the timetable's running-time supplement
distributed over its sections for the least traction energy.

Each section's energy as a function of its running time, E_i(T), is that of its
energy-optimal driving for that time: seed 002's dynamic programme (core/targets/
strategy.py `solve`) on the section's line, at the full envelope, kept the ato curve's
margin under the limits (the minimum running times' rule), the train's departure (dead
time, lag, the rise to start speed: profiles.departure_time) added to the programme's
time, which starts moving at once. The programme prices a second of running time at
lambda (kW): each lambda gives a point (T, E) where the slope of E_i is -lambda, so a
sweep of lambda samples the curve with its marginal energy; between the points the curve
is the lower convex hull, piecewise linear.

With the dwells fixed and the train at a standstill at every stop, the journey's energy
is the sum of its sections', so the least-energy split of the running time gives every
section the same marginal energy dE/dT = -lambda: one multiplier for the whole journey.
`allocate` finds it on the curves exactly (convex allocation: every section's segments,
steepest saving first, until the supplement is spent); each section is then driven by the
programme in its allocated time (`SectionProblem.driven`). `best_split` is the check: the
exact optimum of the separable problem over a fine grid of running-time splits, every
section choosing among all the programme's runs made for it (the staircase "least energy
of a run that arrives within T"), by dynamic programming over the sections.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..train.lines import for_train
from ..train.plant import TrainParameters
from . import strategy
from .profiles import departure_time
from .timetable import JourneySection, Timetable, section_line

STAGE_LENGTH = 100.0     # m: the dynamic programme's stages (seed 002's) ...
MIN_STAGES = 80          # ... but at least this many in a short (metro) section
HIGHEST_PRICE = 1.0e5    # kW per s: the dynamic programme drives flat out at this price
CURVE_RESOLUTION = 0.01  # the energy curve's points at most this share of its time apart
MIN_PRICE_RATIO = 1.02   # ... unless their prices are this close (a jump of the optimum)
MAX_CURVE_POINTS = 120
SPLIT_STEP = 0.1         # s: the grid of best_split's running times
# The programme's choices for a section: seed 002's CONTROLS, gentler traction and
# braking (1/10, 1/20 of the envelope) and a landing exactly on the stage's cap or on the
# highest speed the rest of the run allows (strategy.LAND), on a finer speed grid than
# seed 002's: a metro section's least-energy run tops its speed up by a little where a
# limit rises, holds a limit on a descent and brakes along its braking curve into the
# stop, which fractions of the envelope alone buy dearer (the independent programme of
# studies/energy_optimum.py put those sections 4-8 % below seed 002's choices' runs, and
# still 1-2 % below the fractions' without the landing: each braking stage a little under
# the curve, the stop reached later).
FRACTIONS = (1.0, 0.75, 0.5, 0.25, 0.1, 0.05)
SECTION_CONTROLS = (*(("traction", f) for f in FRACTIONS), ("cruise", 0.0), ("coast", 0.0),
                    *(("brake", f) for f in reversed(FRACTIONS)), (strategy.LAND, 0.0))
SECTION_SPEED_STEP = 0.05  # m/s


class EnergyCurve(NamedTuple):
    """A section's least energy against its running time: the lower convex hull of the
    dynamic programme's points, time increasing, energy decreasing."""

    times: np.ndarray     # s, standstill to standstill
    energies: np.ndarray  # kWh of traction

    def energy(self, time: float) -> float:
        return float(np.interp(time, self.times, self.energies))

    def marginal(self) -> np.ndarray:
        """dE/dT of each segment between the points, kW (negative: time saves energy)."""
        return np.diff(self.energies) / np.diff(self.times) * 3600.0


@dataclass(frozen=True)
class SectionProblem:
    """One section of a journey as the dynamic programme drives it."""

    section: JourneySection
    problem: strategy.Problem
    departure: float  # s the train takes to start moving, added to the programme's time

    def drive(self, price: float) -> strategy.Strategy:
        """The energy-optimal run at `price` (kW per s of running time)."""
        problem = self.problem
        return strategy.solve(problem.track, problem.train, problem.efficiency, None,
                              lam=price, controls=SECTION_CONTROLS,
                              speed_step=SECTION_SPEED_STEP)

    def driven(self, running_time: float) -> strategy.Strategy:
        """The energy-optimal run in `running_time` (s, standstill to standstill; it may
        arrive up to a jump of the programme's optimum early)."""
        problem = self.problem
        return strategy.solve(problem.track, problem.train, problem.efficiency,
                              running_time - self.departure, controls=SECTION_CONTROLS,
                              speed_step=SECTION_SPEED_STEP)


def section_problems(timetable: Timetable, values: dict) -> tuple[SectionProblem, ...]:
    """Each section of the journey for the run's nominal train (`values`: plant.* and
    profile.ato.*)."""
    train = TrainParameters.from_values(values)
    runs = for_train(timetable.line, values)  # its limits capped at the train's top speed
    problems = []
    for section in timetable.sections:
        line = section_line(runs, section.start, section.end)
        length = section.end - section.start
        track = strategy.Track.of(line, train, min(STAGE_LENGTH, length / MIN_STAGES),
                                  margin=values["profile.ato.margin"])
        problem = strategy.Problem(track, train, values["plant.efficiency"])
        problems.append(SectionProblem(section, problem, departure_time(values, train)))
    return tuple(problems)


def sampled_runs(section: SectionProblem, longest: float) -> list[tuple[float, float]]:
    """(running time s, energy kWh) of the section's energy-optimal runs from flat out to
    at least `longest` s: prices halved from HIGHEST_PRICE until the run takes that long,
    then more prices between any two whose runs are more than CURVE_RESOLUTION of the
    time apart."""
    runs = {HIGHEST_PRICE: section.drive(HIGHEST_PRICE)}
    price = HIGHEST_PRICE
    while runs[price].time + section.departure < longest and len(runs) < MAX_CURVE_POINTS:
        price /= 2.0
        runs[price] = section.drive(price)
    gap = CURVE_RESOLUTION * (runs[HIGHEST_PRICE].time + section.departure)
    while len(runs) < MAX_CURVE_POINTS:
        prices = sorted(runs)
        wide = [(low, high) for low, high in zip(prices, prices[1:], strict=False)
                if runs[low].time - runs[high].time > gap and high / low > MIN_PRICE_RATIO]
        if not wide:
            break
        for low, high in wide[:MAX_CURVE_POINTS - len(runs)]:
            middle = math.sqrt(low * high)
            runs[middle] = section.drive(middle)
    return sorted((run.time + section.departure, run.energy_kwh) for run in runs.values())


def lower_hull(runs: list[tuple[float, float]]) -> EnergyCurve:
    """The energy curve of (time, energy) points sorted by time: their lower convex hull,
    up to the lowest energy (more time beyond it saves nothing)."""
    points = np.array(runs)
    hull: list[np.ndarray] = []
    for point in points[:int(np.argmin(points[:, 1])) + 1]:
        while len(hull) >= 2 and _cross(hull[-2], hull[-1], point) <= 0.0:
            hull.pop()
        hull.append(point)
    corners = np.array(hull)
    return EnergyCurve(corners[:, 0], corners[:, 1])


def _cross(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Positive when a -> b -> c turns anticlockwise (c above the line through a, b)."""
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


class Allocation(NamedTuple):
    times: tuple[float, ...]  # s per section, standstill to standstill
    marginal: float           # kW: dE/dT of every section with time beyond its least


def allocate(curves: list[EnergyCurve], least: list[float], total: float) -> Allocation:
    """The split of `total` s over the sections with the least energy on their curves,
    each at least its `least` time: all sections' curve segments beyond those times,
    steepest saving first, each taken whole while the supplement lasts, the last in
    part. ValueError if the least times exceed the total or the curves end before it."""
    times = [max(low, curve.times[0]) for low, curve in zip(least, curves, strict=True)]
    supplement = total - sum(times)
    if supplement < 0.0:
        raise ValueError(f"the journey's running time {total:g} s is shorter than its "
                         f"sections can be run ({sum(times):.1f} s)")
    segments = []
    for index, (curve, start) in enumerate(zip(curves, times, strict=True)):
        corners = np.concatenate(([start], curve.times[curve.times > start]))
        energies = [curve.energy(t) for t in corners]
        for k in range(len(corners) - 1):
            slope = (energies[k + 1] - energies[k]) / (corners[k + 1] - corners[k])
            segments.append((slope * 3600.0, index, corners[k + 1] - corners[k]))
    marginal = 0.0
    for slope, index, length in sorted(segments):
        if supplement <= 0.0:
            break
        taken = min(length, supplement)
        times[index] += taken
        supplement -= taken
        marginal = slope
    if supplement > 1e-9:
        raise ValueError(f"the sections' energy curves end {supplement:.1f} s short of the "
                         f"journey's running time {total:g} s")
    return Allocation(tuple(times), marginal)


def uniform(minimums: list[float], total: float) -> tuple[float, ...]:
    """The supplement in proportion to the sections' minimum running times, s."""
    return tuple(m * total / sum(minimums) for m in minimums)


def best_split(runs: list[list[tuple[float, float]]], total: float,
               step: float = SPLIT_STEP) -> tuple[tuple[float, ...], float]:
    """The least-energy choice of one run per section, (running time s, energy kWh), with
    the running times together within `total` s, each counted up to the next multiple of
    `step` beyond the section's fastest run (a grid of splits: dynamic programming over
    the sections, the best energy for every grid time so far): (the chosen times, the
    energy). ValueError if even the fastest runs take longer."""
    fastest = [min(t for t, _ in section) for section in runs]
    cells = int(math.floor((total - sum(fastest)) / step + 1e-9))
    if cells < 0:
        raise ValueError(f"the journey's running time {total:g} s is shorter than its "
                         f"sections' fastest runs ({sum(fastest):.1f} s)")
    best = np.zeros(cells + 1)  # least energy of the sections so far within each cell
    choices = []
    for section, first in zip(runs, fastest, strict=True):
        shifts = [math.ceil((t - first) / step - 1e-9) for t, _ in section]
        options = np.full((len(section), cells + 1), np.inf)
        for k, (shift, (_, energy)) in enumerate(zip(shifts, section, strict=True)):
            if shift <= cells:
                options[k, shift:] = best[:cells + 1 - shift] + energy
        choices.append(np.argmin(options, axis=0))
        best = options.min(axis=0)
    times, cell = [], cells
    for section, first, chosen in zip(runs[::-1], fastest[::-1], choices[::-1], strict=True):
        t = section[int(chosen[cell])][0]
        times.append(t)
        cell -= math.ceil((t - first) / step - 1e-9)
    return tuple(times[::-1]), float(best[cells])


def point(run: strategy.Strategy, section: SectionProblem) -> tuple[float, float]:
    """(running time s standstill to standstill, energy kWh) of a run of the section."""
    return run.time + section.departure, run.energy_kwh


@dataclass(frozen=True)
class JourneyPlan:
    """The journey's sections, their minimum running times (s), the programme's runs
    sampled for each, the allocation on their curves and each section driven in its
    allocated time."""

    sections: tuple[SectionProblem, ...]
    minimums: tuple[float, ...]
    runs: tuple[list[tuple[float, float]], ...]
    allocation: Allocation
    driven: tuple[strategy.Strategy, ...]

    @property
    def energy_kwh(self) -> float:
        return sum(run.energy_kwh for run in self.driven)


def plan_journey(timetable: Timetable, values: dict, minimums: tuple[float, ...]
                 ) -> JourneyPlan:
    """The least-energy split of the timetable's running time for the run's nominal train
    (`values`), each section at least its minimum running time (timetable.
    check_minimum_times)."""
    sections = section_problems(timetable, values)
    if timetable.journey:  # a TTOBench journey's windows fix each section's time
        return windowed_plan(timetable, sections, minimums)
    total = timetable.running_time
    supplement = total - sum(minimums)
    runs = tuple(sampled_runs(section, minimum + supplement)
                 for section, minimum in zip(sections, minimums, strict=True))
    allocation = allocate([lower_hull(r) for r in runs], list(minimums), total)
    driven = tuple(section.driven(t)
                   for section, t in zip(sections, allocation.times, strict=True))
    return JourneyPlan(sections, minimums, runs, allocation, driven)


def windowed_plan(timetable: Timetable, sections: tuple[SectionProblem, ...],
                  minimums: tuple[float, ...]) -> JourneyPlan:
    """A TTOBench journey's plan: each section driven in its own running time, its
    arrival window's latest less its departure (the stops' windows leave no time to move
    between sections, and a section's least energy falls with its time); no marginal
    energy across sections (NaN)."""
    times = tuple(section.running_time for section in timetable.sections)
    driven = tuple(problem.driven(t) for problem, t in zip(sections, times, strict=True))
    runs = tuple([point(run, problem)] for run, problem in zip(driven, sections, strict=True))
    return JourneyPlan(sections, minimums, runs, Allocation(times, math.nan), driven)


def passing_time(run: strategy.Strategy, section: SectionProblem, position: float) -> float:
    """When `run` of `section` passes `position` (m along the line), s after its
    departure (the train's departure time included, as its running time counts)."""
    speeds = np.maximum(0.5 * (run.speeds[1:] + run.speeds[:-1]), 1e-6)
    times = np.concatenate(([0.0], np.cumsum(np.diff(run.positions) / speeds)))
    return section.departure + float(np.interp(position - section.section.start,
                                               run.positions, times))


class Comparison(NamedTuple):
    uniform_times: tuple[float, ...]             # s: the supplement pro rata
    uniform_runs: tuple[strategy.Strategy, ...]  # each section driven in that time
    best_times: tuple[float, ...]                # s: best_split's
    best_energy_kwh: float


def compare(plan: JourneyPlan, total: float) -> Comparison:
    """The uniform allocation driven, and the exact optimum over every run the programme
    made for each section (sampled, uniform, allocated)."""
    times = uniform(list(plan.minimums), total)
    runs = tuple(section.driven(t) for section, t in zip(plan.sections, times, strict=True))
    known = [sampled + [point(u, s), point(a, s)] for sampled, u, a, s in zip(
        plan.runs, runs, plan.driven, plan.sections, strict=True)]
    best_times, best_energy = best_split(known, total)
    return Comparison(times, runs, best_times, best_energy)
