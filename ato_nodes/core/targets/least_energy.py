"""A section driven on time for the least energy (profile.journey.driving least_energy),
ROS-free: the ato curve kept under the section's least-energy run.

The cruise curve meets a running time at the lowest cruise speed; the least traction
energy for that time runs faster, coasts (and holds a limit on a descent) instead, and a
journey driven on cruise curves draws about half as much again as its optimum
(docs/results.md "Energy optimum"). Here each section's target is its ato curve (the same
rates, margin, envelope share, rounding, departure and eased stop) kept under a Ceiling:
a run of the journey's section programme (core/targets/journey.py: seed 002's dynamic
programme with gentler controls on a fine speed grid) at a price of time, planned for
what the curve can ask: the share of the envelope, the forces capped at the curve's
planned acceleration and braking (`programme_train`), under the same margin.

The price is bisected on the curve's own running time (standstill to standstill) for the
nominal train (plant.*), whose runs are kept per process: every train the ATO weighs
heavier shares them. A run's curve, for the weighed train, is never faster than the run
(the ceiling only lowers it), so the train takes the slowest of those runs whose curve
still meets the time and, at its fastest, passes no passing point after its window
(served.timed_curve), and the curve's cruise bisection caps that run's top speeds to meet
the time to the curve's bits (AtoCurve._cruise); passing windows then cap it as they cap
a cruise curve (one that passes a point late is capped after it, its top speeds before it
rising back towards the run's).
"""

from __future__ import annotations

import dataclasses
import functools
import math

from ..train.line import Line
from ..train.plant import TrainParameters
from . import strategy
from .journey import (HIGHEST_PRICE, MIN_STAGES, SECTION_CONTROLS, SECTION_SPEED_STEP,
                      STAGE_LENGTH)
from .profiles import AtoCurve, Ceiling, ato_curve

PRICE_STEPS = 9     # bisections of the price (journey.HIGHEST_PRICE down to LOWEST_PRICE):
                    # the bracket's ends 1.02 apart at the end
LOWEST_PRICE = 1.0  # kW per s of running time: a run far slower than any timetable's


def programme_train(train: TrainParameters, values) -> TrainParameters:
    """`train` as the programme plans the target for: the curve's share of its envelope
    (profile.envelope_share, all of it at 0), its forces capped at what gives the curve's
    planned acceleration and braking on the level (profile.ato.*), so that the run asks
    nothing the curve would not."""
    share = values["profile.envelope_share"] or 1.0
    inertia = train.mass * (1.0 + train.gamma)  # kN per m/s^2
    return dataclasses.replace(
        train, max_traction_power=share * train.max_traction_power,
        max_traction_force=min(share * train.max_traction_force,
                               inertia * values["profile.ato.acceleration"]),
        max_brake_power=share * train.max_brake_power,
        max_brake_force=min(share * train.max_brake_force,
                            inertia * values["profile.ato.deceleration"]))


def run_ceiling(track: strategy.Track, train: TrainParameters, price: float) -> Ceiling:
    """The programme's least-energy run at `price` (kW per s) as a ceiling."""
    run = strategy.solve(track, train, 1.0, None, lam=price, controls=SECTION_CONTROLS,
                         speed_step=SECTION_SPEED_STEP)
    return Ceiling(tuple(run.positions.tolist()), tuple(run.speeds.tolist()))


def curve_of(values, line: Line, train: TrainParameters, ceiling: Ceiling) -> AtoCurve:
    """`train`'s ato curve on `line` under `ceiling`, uncapped (its fastest)."""
    return ato_curve(values, dataclasses.replace(line, planned_run_time=None), train, ceiling)


def curve_time(values, line: Line, train: TrainParameters, ceiling: Ceiling) -> float:
    """The running time of `train`'s ato curve on `line` under `ceiling`, uncapped, s."""
    return curve_of(values, line, train, ceiling).planned_run_time


def runs(values, line: Line, nominal: TrainParameters) -> tuple[tuple[float, Ceiling], ...]:
    """The runs the price's bisection made for the nominal train on `line` (a section,
    its planned_run_time the time to meet), each with its curve's running time, fastest
    first; kept per process (values: the journey's TABLE_INPUTS)."""
    return _runs(line, nominal, tuple(sorted(values.items())))


@functools.lru_cache(maxsize=64)
def _runs(line: Line, nominal: TrainParameters, inputs: tuple
          ) -> tuple[tuple[float, Ceiling], ...]:
    values = dict(inputs)
    train = programme_train(nominal, values)
    track = strategy.Track.of(line, train, min(STAGE_LENGTH, line.stop_position / MIN_STAGES),
                              margin=values["profile.ato.margin"])
    fastest = run_ceiling(track, train, HIGHEST_PRICE)
    made, planned = [(curve_time(values, line, nominal, fastest), fastest)], line.planned_run_time
    low, high = math.log(LOWEST_PRICE), math.log(HIGHEST_PRICE)
    for _ in range(PRICE_STEPS if made[0][0] < planned else 0):
        middle = 0.5 * (low + high)
        ceiling = run_ceiling(track, train, math.exp(middle))
        made.append((curve_time(values, line, nominal, ceiling), ceiling))
        low, high = (middle, high) if made[-1][0] > planned else (low, middle)
    return tuple(sorted(made, key=lambda run: run[0]))


def ceilings(values, line: Line, nominal: TrainParameters) -> tuple[Ceiling | None, ...]:
    """The runs a curve on `line` may keep under, slowest first: the nominal train's runs
    whose curve meets the line's planned time (a train weighed heavier may need a faster
    one: served.timed_curve takes the first that meets it), then None, the cruise curve,
    for a time none of them meets (the programme's stages round a limit's change down:
    its flat-out run is a little slower than the curve at the limits)."""
    made = runs(values, line, nominal)
    return (*(ceiling for time, ceiling in reversed(made) if time <= line.planned_run_time),
            None)
