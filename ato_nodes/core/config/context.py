"""The read-only run context every component receives at construction.

It holds what an ATO knows before the run starts: the control period, its train
(the preset's parameters, core.plant.TrainParameters, at the mass the ATO knows:
train.mass_reading, the load weighing's when train.load_weighing, if heavier than
the nominal), the line,
and the planned target (the chosen profile kind's plan), with the preview of
that plan over any horizon. Built from the same values in every runner, so a
component sees the same context in a node and in simulate().
"""

from __future__ import annotations

import functools
import math

from ..base.errors import ScenarioError
import numpy as np

from ..targets.horizons import ProfileSettings, plan_horizon
from ..targets import least_energy, profiles, served, timetable
from ..control.estimation import mass_prior_sigma
from ..targets.replan import replan_settings
from ..targets.profiles import (NO_RAMP, DepartureRamp, departing, departure_ramp,
                                feasible_plan, plan_table)
from ..targets.served import START
from ..train.line import Line
from ..train.lines import line_of
from ..train.plant import OPEN_TRACK, TrainParameters
from .components import PROFILES
from .schema import steps


def ato_train(values, mass: float | None = None) -> TrainParameters:
    """The train the ATO plans and controls with: the nominal one (plant.*) at the mass
    it knows, plant.mass times train.mass_reading (or `mass`), but never lighter than the nominal
    train (the nominal one itself up to a reading of 1): a lighter train could give more
    specific force (N/kN), but the command limits (controller.u_min, u_max, N/kN) are
    the nominal train's, so a plan at the light train's envelope share would ask for
    force the limiter does not let through. Its resistance as the real train's grows
    with the load (TrainParameters.loaded: plant.davis_absolute)."""
    nominal = TrainParameters.from_values(values)
    reading = values["train.mass_reading"] if mass is None else mass
    return nominal if reading <= 1.0 else nominal.loaded(reading,
                                                         values["plant.davis_absolute"])


def planned_mass(values) -> float:
    """The mass the plan is made for at departure (over the nominal): the reading, or with
    profile.replan.enabled the reading plus profile.replan.sigmas of its uncertainty, at most
    the crush load train.load_weighing_max (core/targets/replan.py)."""
    reading = values["train.mass_reading"]
    if not values["profile.replan.enabled"]:
        return reading
    bound = reading * (1.0 + values["profile.replan.sigmas"] * mass_prior_sigma(values))
    return min(bound, values["train.load_weighing_max"] or math.inf)


# The process's caches of built plans, each keyed by what its plans are built from: the
# plan a run's validation builds is the one its simulation reads, and runs that share a
# plan (a tuning's candidates, a set of trains run again) share it.
PLAN_CACHES = (profiles._ato_curve, profiles.feasible_plan, profiles._driven_again,
               served._journey_tables, least_energy._runs, timetable._minimum_running_time)


def forget_plans() -> None:
    """Empty PLAN_CACHES: the next run builds its plan anew (what
    benchmarks/benchmark_steps.py times as the plan's cost)."""
    for cache in PLAN_CACHES:
        cache.cache_clear()


class RunContext:
    def __init__(self, values, line: Line | None = None):
        self.values = values
        self.period = values["run.period"]
        self.steps = steps(values)
        self.train = ato_train(values)
        # the train the plan is made for: the controllers' own, or with profile.replan the
        # heaviest the reading admits (core/targets/replan.py)
        self.planned_mass = planned_mass(values)
        self.plan_train = ato_train(values, self.planned_mass)
        self.line = line_of(values) if line is None else line

    @functools.cached_property
    def berth_mark(self) -> float:
        """The stop mark a train standing within profile.berth of has arrived at, m (NaN:
        no berth); ScenarioError (one line) for a berth on a plan with no such stop."""
        if not self.values["profile.berth"]:
            return math.nan
        plan, line = self.plan, self.line
        if (not plan.position_indexed or hasattr(plan, "observe") or line is None
                or line.stop_position <= 0.0):
            raise ScenarioError(f"profile.berth applies to a position-indexed plan to a line's "
                                f"stop, not to profile.kind {self.values['profile.kind']} "
                                f"(a journey berths by profile.journey.berth)")
        return line.stop_position

    @functools.cached_property
    def departure(self) -> DepartureRamp:
        """The ramp a position-indexed plan's target leaves the run's start with
        (profile.departure_jerk; a journey ramps each departure itself); ScenarioError (one
        line) for a plan that does not start from standstill at a departure point."""
        values, plan = self.values, self.plan
        if not values["profile.departure_jerk"] or hasattr(plan, "journey"):
            return NO_RAMP
        if not plan.position_indexed:
            raise ScenarioError(f"profile.departure_jerk applies to a position-indexed plan "
                                f"from standstill (the ato curve, the strategy, a journey), "
                                f"not to profile.kind {values['profile.kind']}")
        return departure_ramp(values, self.train, plan.speed(0.0, 0.0))

    def target(self, t: float, position: float) -> float:
        """The plan's target at time t with the head at `position`, m/s, under the
        departure ramp."""
        return departing(self.departure, t, self.plan.speed(t, position))

    @functools.cached_property
    def plan(self):
        """The planned target: speed(t, position) in m/s, and position_indexed; made
        drivable by the nominal train when profile.envelope_share or profile.jerk asks."""
        values = self.values
        plan = PROFILES.chosen(values).factory(values, self)
        share, jerk = values["profile.envelope_share"], values["profile.jerk"]
        if not (share or jerk) or plan.shapes_itself:
            return plan
        if plan.position_indexed:
            raise ScenarioError(f"profile.envelope_share and profile.jerk apply to time-indexed "
                                f"profiles and the ato curve, not to profile.kind "
                                f"{values['profile.kind']}")
        return feasible_plan(plan, self.train, share, jerk, self.period, self.steps)

    @functools.cached_property
    def profile_settings(self) -> ProfileSettings:
        """The profile step's settings (core/targets/horizons.py; the line's limits as
        tuples: Python reads them fast); ScenarioError (one line) for a plan it cannot read:
        a position-indexed plan without its PlanTable, a time-indexed one with limits."""
        values, plan = self.values, self.plan
        kind = values["profile.kind"]
        table = plan.table() if plan.position_indexed else None
        if plan.position_indexed and table is None and not hasattr(plan, "journey"):
            raise ScenarioError(f"profile.kind {kind}: a position-indexed plan gives the "
                                f"table its targets are read from (Plan.table())")
        if not plan.position_indexed and plan.limits_speed:
            raise ScenarioError(f"profile.kind {kind}: a time-indexed plan's own speed limits "
                                f"are not read (the line's apply): its limits_speed is False")
        return ProfileSettings(
            float(self.period), int(values["controller.preview"]), bool(plan.position_indexed),
            plan_table((), ()) if table is None else table, self.departure,
            self.line.tables if self.line is not None else OPEN_TRACK,
            float(values["profile.approach_step"]), float(values["profile.berth"]),
            float(self.berth_mark), replan_settings(values, plan))

    def horizon(self, step: int, position: float, count: int) -> list[float]:
        """The plan's targets of steps step .. step + count, from `position` at step:
        exact for time-indexed plans; for position-indexed plans along the planned
        trajectory ds/dt = v(s) from `position` (horizons.plan_horizon)."""
        plan, h = self.plan, self.period
        if not plan.position_indexed:
            return [plan.speed((step + i) * h, position) for i in range(count + 1)]
        horizon = np.empty(count + 1)
        plan_horizon(self.profile_settings, getattr(plan, "journey", None),
                     getattr(plan, "state", START), step, position, horizon)
        return horizon.tolist()
