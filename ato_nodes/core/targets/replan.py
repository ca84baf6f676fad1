"""Plans re-made from the on-board estimate (profile.replan.*), ROS-free.

The plan is made for the heaviest train the ATO's knowledge admits, not for one reading:
at departure the mass's prior, train.mass_reading (1 + k sigma), sigma the estimator's
mass_prior_sigma and k = profile.replan.sigmas (config/context.py planned_mass); then the
on-board estimate (core/control/estimation.py, the controller's mass_factor and
mass_sigma outputs), mass + k sigma; never above the crush load (train.load_weighing_max:
the heaviest the train can be, where an estimate errs high). Why the bound and not the
estimate: the mass is seen only while the train runs at its envelope (estimation.py),
that is once a plan asks more than the train has, when the tracking already suffers; a
plan for the bound leaves that train its reserve. A train with no load weighing
(estimator.mass_sigma its possible range) is planned for the heavy end of the range; a
reading the estimate contradicts is replaced as the estimate firms up.

Mid-run (the ato curve, profile.kind ato): when the bound moves more than
profile.replan.mass_change (a share) from the mass the plan was made for, the profile
step asks for a re-plan (replan_request, written once for the node and both loops); its
runner (core/run/stages.ProfileStage.replan, called by the profile node and by the loop
of core/run/fast_loop.py between two chunks of steps, at the same step) re-plans the
curve from the train's state: from its position and speed at that step, for the time
left to the planned arrival (profile.ato.on_time), for the new mass; the curve before that
position is kept. Never within profile.replan.stop_distance of the stop mark, never with
the train's belt on a neutral section, and at most once per profile.replan.interval
(each re-plan moves the target's acceleration: the curve starts from the train's speed
with its acceleration rounded up from 0).

Degraded adhesion (profile.degraded.enabled, the ato curve, with odometry.enabled): the
on-board localisation reads the adhesion the rail has from the slips and slides it sees
(core/control/localisation.py adhesion_seen, a factor on Curtius-Kniffler's curve); once
that falls more than profile.degraded.change below what the plan was made for (at first:
any rail), the step asks for a re-plan under the same rules, and the curve is re-planned
asking no more than profile.degraded.margin of the force that rail gives at the plan's
top speed (adhesion falls with speed: it holds at every speed below), on the motored axles
for traction and on the braked ones for braking (degraded_plan: a curve at
profile.envelope_share has the ATO train's envelope capped there, its passes keeping the
line's gradients within it; any other, its rates). The re-plan is said on the events
topic as a degraded adhesion. It cannot save a stop whose braking has begun: it needs a
slip or a slide seen before (a departure on bad rail slips).

Journeys and strategies are planned for the bound at departure (the plan's train), not
re-planned mid-run, for the mass or the adhesion.

Units: m, s, m/s; masses over the nominal plant.mass.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from ..base.spec import PROFILE_NODES, param
from ..base.units import MS_TO_KMH
from ..train.adhesion import adhesion_coefficient
from ..train.line import LineTables, in_neutral_section
from ..train.plant import TrainParameters
from .profiles import PlanTable, ato_curve_arguments, new_ato_curve, plan_table, table_speed
from .timetable import section_line

PARAMETERS = (
    param("profile.replan.enabled", False, "plan for the heaviest train the ATO's knowledge "
          "admits: the mass reading plus profile.replan.sigmas of its uncertainty "
          "(estimator.mass_sigma) at departure, then the on-board estimate's; the ato curve "
          "re-planned mid-run from the train's state when that moves (needs estimator.enabled "
          "and a controller kind that estimates; false = the reading alone, once)",
          PROFILE_NODES),
    param("profile.replan.sigmas", 2.0, "the plan's mass is the estimate plus this many of "
          "its sigmas", PROFILE_NODES, 0.0, 5.0),
    param("profile.replan.mass_change", 0.03, "re-plan when the estimate's bound moves this "
          "share from the mass the plan was made for", PROFILE_NODES, 0.001, 1.0),
    param("profile.replan.interval", 5.0, "at most one re-plan in this time, s",
          PROFILE_NODES, 0.0, 1e4),
    param("profile.replan.stop_distance", 100.0, "no re-plan within this distance of the "
          "stop mark, m", PROFILE_NODES, 0.0, 1e5),
    param("profile.degraded.enabled", False, "degraded adhesion: re-plan the ato curve "
          "within the adhesion the slips and slides show (needs odometry.enabled with its "
          "accelerometer or radar)", PROFILE_NODES),
    param("profile.degraded.margin", 0.7, "the most the re-planned curve asks of the rail "
          "seen, over the force it gives at the plan's top speed", PROFILE_NODES, 0.05, 1.0),
    param("profile.degraded.change", 0.1, "re-plan when the adhesion seen falls this share "
          "below the plan's", PROFILE_NODES, 0.0, 1.0),
)


class ReplanSettings(NamedTuple):
    """What a run fixes for its mid-run re-plans."""

    enabled: bool          # the plan is re-planned mid-run (the ato curve)
    sigmas: float          # k of the bound mass + k sigma
    mass_change: float     # share of the plan's mass the bound must move
    interval: float        # s between two re-plans, at least
    last_position: float   # m, the last position a re-plan may start from (the stop less
                           # profile.replan.stop_distance)
    train_length: float    # m: no re-plan with the belt on a neutral section
    heaviest: float        # the crush load (train.load_weighing_max; inf: none): no plan
                           # for a heavier train, whatever the estimate says
    degraded: bool = False         # re-planned for the adhesion seen (profile.degraded)
    adhesion_change: float = 0.0   # share the adhesion seen must fall below the plan's


SLOPE_LOOK = 1.0  # m: a plan lower this far ahead brakes, higher accelerates

NO_REPLAN = ReplanSettings(False, 0.0, math.inf, math.inf, -math.inf, 0.0, math.inf)


def replan_settings(values, plan) -> ReplanSettings:
    """The run's ReplanSettings: for the ato curve, by the mass with profile.replan.enabled,
    by the adhesion with profile.degraded.enabled."""
    by_mass, degraded = values["profile.replan.enabled"], values["profile.degraded.enabled"]
    if not (by_mass or degraded) or values["profile.kind"] != "ato":
        return NO_REPLAN
    return ReplanSettings(bool(by_mass), float(values["profile.replan.sigmas"]),
                          float(values["profile.replan.mass_change"]),
                          float(values["profile.replan.interval"]),
                          float(plan.positions[-1] - values["profile.replan.stop_distance"]),
                          float(values["plant.length"]),
                          float(values["train.load_weighing_max"] or math.inf),
                          bool(degraded), float(values["profile.degraded.change"]))


@jitable
def replan_request(settings: ReplanSettings, plan: PlanTable, line: LineTables,
                   planned: float, planned_adhesion: float, replanned_at: float, t: float,
                   position: float, mass: float, sigma: float, adhesion: float
                   ) -> tuple[float, float]:
    """(mass, adhesion factor) to re-plan for at `t` (s) with the head at `position` (m),
    from the mass estimate (`mass`, `sigma`; NaN: none yet) against the `planned` mass,
    and from the `adhesion` seen (NaN: none) against the `planned_adhesion`, each the
    planned one's when only the other moves; (NaN, NaN): none. Not within the last
    re-plan's interval, nor while the `plan` brakes: a braking curve re-planned half-way
    jumps, and the estimate is least sure there (the brakes' force steps at their
    largest, the actuator's lag the least known); nor for a lighter train while it
    accelerates (the bound falls as the estimate's sigma shrinks, before the estimate has
    risen to the heavy train it sees: a lighter plan would ask more of it then)."""
    bound = planned
    if settings.enabled and mass == mass:
        # never lighter than the nominal train (context.ato_train), nor heavier than crush
        bound = min(max(mass + settings.sigmas * sigma, 1.0), settings.heaviest)
    by_mass = abs(bound / planned - 1.0) > settings.mass_change
    by_adhesion = settings.degraded and adhesion < planned_adhesion * (
        1.0 - settings.adhesion_change)
    if not (by_mass or by_adhesion) or t - replanned_at < settings.interval or \
            position > settings.last_position:
        return math.nan, math.nan
    ahead, here = table_speed(plan, position + SLOPE_LOOK), table_speed(plan, position)
    if ahead < here:
        return math.nan, math.nan  # braking
    if bound < planned and ahead > here:  # lighter, which would ask more, while accelerating
        bound, by_mass = planned, False
    if not (by_mass or by_adhesion) or in_neutral_section(line, position) or \
            in_neutral_section(line, position - settings.train_length):
        return math.nan, math.nan
    return bound, adhesion if by_adhesion else planned_adhesion


class CurveReplan(NamedTuple):
    """A mid-run re-plan of the ato curve, as the profile node says it and the bag keeps
    it."""

    time: float          # s
    position: float      # m, the head, where the new curve starts
    speed: float         # m/s, its start speed
    mass: float          # the new plan's mass over the nominal
    planned_mass: float  # the old plan's
    adhesion: float = math.inf  # the adhesion factor it is planned within (inf: any)
    traction: float = math.inf  # N/kN, the most it asks of that rail (inf: any)
    braking: float = math.inf

    def text(self) -> str:
        said = (f"the ato curve at {self.time:.1f} s from {self.position:.1f} m at "
                f"{self.speed * MS_TO_KMH:.2f} km/h")
        if self.adhesion < math.inf:
            said = (f"for degraded adhesion (the rail seen at {self.adhesion:.2f} x the dry "
                    f"curve): {said}, within {self.traction:.1f} N/kN of traction and "
                    f"{self.braking:.1f} N/kN of braking")
            if self.mass == self.planned_mass:
                return said
        return (f"{said} for a mass of {self.mass:.3f} x nominal (the on-board estimate; "
                f"planned for {self.planned_mass:.3f})")


LOWEST_ADHESION = 0.05  # of the dry curve (mu 0.017 at standstill): no plan for less


class DegradedPlan(NamedTuple):
    """What a curve within a rail is planned with (degraded_plan)."""

    values: dict                 # the run's, its ato rates capped
    train: TrainParameters       # the ATO's, its force envelope capped
    traction: float              # N/kN: the most the curve asks of the rail
    braking: float


def degraded_plan(values, train: TrainParameters, adhesion: float, table: PlanTable
                  ) -> DegradedPlan:
    """The curve's settings within the rail whose adhesion factor is `adhesion`
    (LOWEST_ADHESION at least): profile.degraded.margin of the force it gives at the top
    speed of the plan `table`, on the motored axles for traction and on the braked ones
    for braking. A curve planned at profile.envelope_share of the ATO's `train`'s force
    envelope has that envelope capped at those forces (the curve's passes keep the line's
    gradients within them); any other, its rates at what those forces give on the level
    (traction less `train`'s basic resistance); neither above the scenario's."""
    top = float(np.max(table.grid[1]))
    if table.squared:
        top = math.sqrt(top)
    rail = (values["profile.degraded.margin"] * 1000.0
            * adhesion_coefficient(top, max(adhesion, LOWEST_ADHESION)))  # N/kN per share
    traction, braking = rail * values["plant.motored_share"], rail * values["plant.braked_share"]
    kilonewtons = train.mass * train.gravity / 1000.0  # per N/kN
    capped = dataclasses.replace(
        train, max_traction_force=min(train.max_traction_force, traction * kilonewtons),
        max_brake_force=min(train.max_brake_force, braking * kilonewtons))
    acceleration, deceleration = values["profile.ato.acceleration"], values[
        "profile.ato.deceleration"]
    if not (values["profile.envelope_share"] > 0.0 and train.limited):
        acceleration = min(acceleration, max(traction - train.resistance(top), 0.0) * train.xi)
        deceleration = min(deceleration, braking * train.xi)
    return DegradedPlan({**values, "profile.ato.acceleration": acceleration,
                         "profile.ato.deceleration": deceleration}, capped, traction, braking)


_CURVE_ARGUMENTS = tuple(inspect.signature(new_ato_curve).parameters)  # in their order


def replanned_table(values, line, train, table: PlanTable, position: float, speed: float,
                    t: float) -> PlanTable:
    """The ato curve's table re-planned for `train` from `position` (m) at `speed` (m/s)
    at `t` (s): table's rows before `position`, then the curve on the rest of `line` to its
    stop from `speed`, on time for the planned arrival (profile.ato.on_time: the line's
    planned running time less `t`; at the limits when that is past).

    A train accelerating when a re-plan comes (the mass shows at the envelope) would run
    ahead of a jerk-rounded curve from its speed, which starts at zero acceleration, by
    about a T / 2 (T = the rounding's time, a the acceleration). So the curve then starts
    as the unrounded one from `speed`, at the new plan's own rate, under the rounded curve
    planned from a T / 2 higher (which it meets once the rounding has caught up): the
    target keeps its speed and nearly its acceleration. A train cruising (the old plan
    flat there: a lighter train's plan, faster) starts on the rounded curve, at zero
    acceleration as it is: the unrounded one would ask the plan's rate at once, and the
    train, its actuator lagging, fall a km/h behind."""
    stop = line.stop_position
    rest = section_line(line, position, stop)
    given = ato_curve_arguments(values, rest, train)
    arguments = dict(zip(_CURVE_ARGUMENTS[:len(given)], given, strict=True))
    arguments.update(start_speed=max(speed, 0.01), floor=values["profile.ato.start_speed"],
                     departure=0.0 if values["profile.ato.on_time"] else None)
    jerk = values["profile.jerk"]
    unrounded_start = jerk > 0.0 and \
        table_speed(table, position + SLOPE_LOOK) > table_speed(table, position)
    if unrounded_start:  # no planned time, no bisection; as near the limits as may be
        sharp = new_ato_curve(**{**arguments, "jerk": 0.0, "margin": 0.5 * arguments["margin"]})
    if values["profile.ato.on_time"] and line.planned_run_time is not None:
        rest = dataclasses.replace(rest, planned_run_time=max(line.planned_run_time - t, 0.0))
        arguments["line"] = rest
    if unrounded_start:
        rounding = max(values["profile.ato.acceleration"],
                       values["profile.ato.deceleration"]) / jerk
        reach = min(max(speed, 1.0) * rounding, sharp.positions[-1])  # about T s ahead
        rising = float(np.interp(reach, sharp.positions, sharp.speeds)) - sharp.speeds[0]
        arguments["start_speed"] = sharp.speeds[0] + 0.5 * max(rising, 0.0)
    curve = new_ato_curve(**arguments)
    speeds = curve.speeds
    if unrounded_start:  # up to where the rounded curve has caught up
        start = sharp.curve(curve.cruise)
        met = np.flatnonzero(start >= speeds)
        ends = met[met > 0][0] if np.any(met > 0) else len(speeds)
        speeds = np.concatenate((start[:ends], speeds[ends:]))
    kept = table.grid[:, table.grid[0] < position]
    ahead = plan_table(curve.positions + position, speeds, stops_at_end=True,
                       limits=curve.limits).grid
    return table._replace(grid=np.concatenate((kept, ahead), axis=1))
