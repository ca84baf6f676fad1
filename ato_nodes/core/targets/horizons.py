"""The profile's step, ROS-free: from each step's position, the target horizons it
publishes (LOOKAHEAD steps ahead), the journey's state, the berth, seed 003's stepped
approach and the speed limit. Plain functions of NamedTuples (settings: what a run
fixes; state: what a step changes), so the profile node's stage and the lockstep loop,
compiled or not (core/run/fast_loop.py), call the same text.

A step's horizon holds the plan's targets of steps k .. k + N (N = controller.preview):
for a time-indexed plan computed once per plan (every run of the plan shares them), for a
position-indexed one along the planned trajectory ds/dt = v(s) from the position
extrapolated to t_k (Heun's method, one step per period). The horizon of step k + 2 is
published at step k, from s_k + 2 (s_k - s_k-1) (error ~ a (2 dt)^2, centimetres).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import compiled, jitable, overload
from ..train.line import Line, LineTables, line_arrays, speed_limit
from .profiles import DepartureRamp, PlanTable, departing, table_limit, table_speed
from .replan import ReplanSettings, replan_request
from .served import START, JourneyState, JourneyTable, journey_limit, journey_speed, observed

LOOKAHEAD = 2  # steps the profile runs ahead of the plant


class ProfileSettings(NamedTuple):
    """What the profile's step reads and none changes."""

    period: float              # s
    preview: int               # N: a horizon holds N + 1 targets
    position_indexed: bool     # horizons from each position (else given once per plan)
    plan: PlanTable            # a position-indexed plan's (empty: time-indexed, a journey)
    departure: DepartureRamp   # how that plan's target leaves the start
    line: LineTables           # the line's limits (where the plan has none of its own)
    approach_step: float       # m/s, seed 003's stepped approach (0: off)
    berth: float               # m, profile.berth (0: off)
    berth_mark: float          # m, the stop it berths at (NaN: none)
    replan: ReplanSettings     # mid-run re-plans from the on-board estimate (replan.py)


class ProfileState(NamedTuple):
    """What the profile carries from one position to the next."""

    last_position: float       # m
    stair: float               # m/s, the stepped approach's stair (NaN: none)
    journey: JourneyState      # a journey's section and arrival (served.observed)
    arrived: bool              # standing in its berth once (profile.berth): for good
    planned_mass: float        # the mass the plan was made for, over the nominal
    replanned_at: float        # s, the last re-plan's (-inf: none)
    request: float             # the mass a re-plan is asked for at this step (NaN: none)
    request_speed: float       # m/s, the train's speed over the step that asked
    planned_adhesion: float    # the adhesion factor the plan was made within (inf: any)
    request_adhesion: float    # the one a re-plan is asked for (the plan's when only the
                               # mass moves; NaN: none)


def profile_start(planned_mass: float) -> ProfileState:
    """The profile's state at the start, its plan made for `planned_mass`."""
    return ProfileState(0.0, math.nan, START, False, planned_mass, -math.inf, math.nan,
                        math.nan, math.inf, math.nan)


@jitable
def profile_step(settings: ProfileSettings, journey: JourneyTable | None, state: ProfileState,
                 k: int, position: float, located_speed: float, targets, mass: float,
                 mass_sigma: float, adhesion: float) -> ProfileState:
    """Position s_k of step k in (and the localisation's speed then, `located_speed`; NaN:
    the train's speed is its travel over the last step, on the true position -- a located
    position's step holds the filter's corrections, a few cm that are 0.3 m/s over one
    step, where a re-plan starts from it): the horizons to publish now written into `targets`
    (steps x (N + 1): rows 0 .. 2 at k = 0, row k + 2 after; a time-indexed plan's rows
    hold its horizons already), each row's first entry under the stepped approach; the
    state after. Arrived in its berth, the horizons are zero, for good. `mass`,
    `mass_sigma`: the on-board estimate after the step before (NaN: none), `adhesion`: the
    adhesion factor the localisation has seen by this step (NaN: none), from which the
    state asks for a re-plan (replan.py; its runner makes it after this step)."""
    travel = position - state.last_position if k else 0.0  # over the last step
    speed = travel / settings.period if located_speed != located_speed else located_speed
    stair, journey_state = state.stair, state.journey
    if journey is not None:  # its section and when the train stood at its end
        journey_state = observed(journey, journey_state, k * settings.period, position, speed)
    arrived = state.arrived or has_arrived(k, travel, position, settings.berth_mark,
                                           settings.berth)
    first = 0 if k == 0 else k + LOOKAHEAD
    for step in range(first, k + LOOKAHEAD + 1):
        if step < len(targets):
            if arrived:
                targets[step, :] = 0.0
            elif settings.position_indexed:
                plan_horizon(settings, journey, journey_state, step,
                             position + LOOKAHEAD * travel if k else position, targets[step])
            targets[step, 0], stair = approach(settings.approach_step, stair,
                                               targets[step, 0], speed)
    request, request_adhesion = replan_request(
        settings.replan, settings.plan, settings.line, state.planned_mass,
        state.planned_adhesion, state.replanned_at, k * settings.period, position, mass,
        mass_sigma, adhesion)
    if request == request:
        return ProfileState(position, stair, journey_state, arrived, state.planned_mass,
                            k * settings.period, request, speed, state.planned_adhesion,
                            request_adhesion)
    return ProfileState(position, stair, journey_state, arrived, state.planned_mass,
                        state.replanned_at, math.nan, math.nan, state.planned_adhesion,
                        math.nan)


@jitable
def has_arrived(k: int, travel: float, position: float, mark: float, berth: float) -> bool:
    """Whether the train, `travel` m over the step before step `k`, stands still within
    `berth` of the stop `mark` (NaN: none): profile.berth."""
    return k > 0 and travel == 0.0 and abs(mark - position) < berth


@jitable
def plan_horizon(settings: ProfileSettings, journey: JourneyTable | None, state: JourneyState,
                 step: int, position: float, horizon) -> None:
    """A position-indexed plan's targets of steps step .. step + N into `horizon`, along
    the planned trajectory from `position` at `step` (Heun's method, one step per
    period)."""
    h = settings.period
    horizon[0] = plan_target(settings, journey, state, step * h, position)
    for i in range(1, len(horizon)):
        t, v = (step + i) * h, horizon[i - 1]
        ahead = plan_target(settings, journey, state, t, position + h * v)
        position += 0.5 * h * (v + ahead)
        horizon[i] = plan_target(settings, journey, state, t, position)


def plan_target(settings: ProfileSettings, journey: JourneyTable | None, state: JourneyState,
                t: float, position: float) -> float:
    """A position-indexed plan's target: a journey's in its state, else the table's under
    the departure ramp."""
    target = table_target if journey is None else journey_target
    return target(settings, journey, state, t, position)


@jitable(inline=True)
def journey_target(settings: ProfileSettings, journey: JourneyTable, state: JourneyState,
                   t: float, position: float) -> float:
    return journey_speed(journey, state, t, position)


@jitable(inline=True)
def table_target(settings: ProfileSettings, journey: None, state: JourneyState, t: float,
                 position: float) -> float:
    return departing(settings.departure, t, table_speed(settings.plan, position))


if overload is not None:  # compiled code chooses while compiling, and inlines the choice:
    # a call handed the journey counts the references of its eight arrays in and out, 21
    # times a step
    @overload(plan_target, inline="always", strict=False)
    def _chosen_target(settings, journey, state, t, position):
        from numba.core import types  # (numba is there: overload is)
        return table_target if isinstance(journey, types.NoneType) else journey_target


@jitable
def approach(step_size: float, stair: float, target: float, speed: float):
    """Seed 003's stepped approach, (target, stair) (NaN: no stair): while the target is
    more than one step above the speed, the published target is a stair one step above
    the speed, held until the train is within a quarter step of it. Only upwards: a
    target below the speed is a braking curve protecting a limit or the stop, never
    softened; a stair held while the target fell stays under it."""
    if step_size <= 0.0 or target - speed <= step_size:
        return target, math.nan
    if stair != stair or abs(stair - speed) < step_size / 4:
        stair = speed + step_size
    return min(stair, target), stair


@jitable
def plan_speed_limit(settings: ProfileSettings, journey: JourneyTable | None,
                     position: float) -> float:
    """The limit with the head at `position`, m/s: the plan's own (a journey's, the ATO
    curve's tail rule) where it has them, else the line's, else none (inf)."""
    if journey is not None:
        return journey_limit(journey, position)
    if settings.plan.limits_speed:
        return table_limit(settings.plan, position)
    if settings.line.limits_end > settings.line.tunnels_end:
        return speed_limit(settings.line, position)
    return math.inf


def _limits_at(settings: ProfileSettings, journey: JourneyTable | None, positions: np.ndarray
               ) -> np.ndarray:
    limits = np.empty(len(positions))
    for i in range(len(positions)):
        limits[i] = plan_speed_limit(settings, journey, positions[i])
    return limits


_compiled_limits_at = compiled(_limits_at)


def plan_speed_limits(settings: ProfileSettings, journey: JourneyTable | None,
                      line: Line | None, positions: np.ndarray) -> np.ndarray:
    """plan_speed_limit at each of `positions` (m), m/s, for the settings made on `line`:
    compiled when numba is installed (the line read as one array, as the loop reads it),
    the same bits."""
    positions = np.asarray(positions, dtype=float)
    if _compiled_limits_at is None:
        return _limits_at(settings, journey, positions)
    return _compiled_limits_at(settings._replace(line=line_arrays(line)), journey, positions)
