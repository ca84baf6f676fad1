"""A journey as the target (profile.kind journey), ROS-free: the stops of a timetable
(core/targets/timetable.py) served one after another.

Within a section the target is the section's ato curve (core/targets/profiles.py, the
run's profile.ato.*, envelope share and jerk) on the section as its own line
(timetable.section_line), on time for the timetable's running time less
profile.journey.recovery when profile.ato.on_time: the curve bisects its cruise speed on
that time, standstill to standstill. At the section's end the curve's target is 0 into
the stop mark; once the train stands there it is held at 0 (the controller's holding
brake holds it) until it leaves: at the timetable's departure, or, when it arrived late,
at its arrival plus the station's dwell (the line file's, the least its passengers
need); then the next section's curve, whose start_speed starts the train. The last stop
holds to the end.

The target then depends on more than the time and position: on the section being served
and on when the train arrived at its end. That is the profile's state (JourneyState),
derived from what the profile receives and nothing else: each step's position s_k at
t_k = k * run.period and its travel over the last step (`observed`, called by
core/run/stages.ProfileStage in the node and simulate(), and by the compiled loop
alike). The run clock's 0 is the journey's first departure.

A horizon (RunContext.horizon) reads the target with the state of its step: a train
standing at a stop sees its departure coming, at the time it will happen. A train still
running sees the stop and then 0: it cannot leave within a horizon, since it leaves at
least a dwell after it arrives (seconds; a horizon is LOOKAHEAD + controller.preview
steps).

The tables (JourneyTable) are the sections' curves one after another, read by the same
functions in Python and compiled code (core/run/fast_loop.py), to the same bits.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from ..base.errors import ScenarioError
from ..base.kernels import jitable
from ..base.registry import Component, Plan
from ..base.spec import PROFILE_NODES, param
from .profiles import ATO_PARAMETERS, PlanTable, ato_curve, cell_of, table_limit, table_speed
from .timetable import Timetable, load_timetable, section_line

STANDSTILL = 0.01  # m/s: slower over a step counts as standing (a held train does not move)

JOURNEY_PARAMETERS = (
    param("profile.journey.timetable", "", "timetable file (msg_config/timetables/*.yaml) of "
          "the journey to drive, of the run's line.file and plant.train; relative to the "
          "scenario file, else to msg_config/", PROFILE_NODES),
    param("profile.journey.berth", 1.0, "a train standing less than this before a stop mark, "
          "or past it, has arrived there and is held until it leaves, m", PROFILE_NODES,
          0.01, 100.0),
    param("profile.journey.recovery", 0.0, "each section's curve is planned this much inside "
          "its running time (with profile.ato.on_time), kept back for what the curve does not "
          "count (the holding brake's release, the tracking's lag); an early train waits for "
          "its departure at the next stop, s", PROFILE_NODES, 0.0, 60.0),
)


class JourneyTable(NamedTuple):
    """A journey as the target reads it: section i's ato curve is grid[:, bounds[i]:
    bounds[i + 1]] (positions from the section's start, speeds, the belt's limits);
    the section runs from stops[i] to stops[i + 1] (m along the line); the train may
    leave its end at departures[i] (s, run clock; inf at the last stop), or dwells[i]
    after it arrived there if later."""

    grid: np.ndarray        # 3 x points
    bounds: np.ndarray      # sections + 1 column indices
    stops: np.ndarray       # sections + 1 positions, m
    departures: np.ndarray  # sections, s
    dwells: np.ndarray      # sections, s
    berth: float            # m (profile.journey.berth)


class JourneyState(NamedTuple):
    """What the profile carries from step to step on a journey."""

    section: int    # the section served: the train is on it or stands at its end
    arrival: float  # s: when the train was found standing at the section's end (NaN: not yet)


START = JourneyState(0, math.nan)  # the first section, from the first departure at t = 0


@jitable
def section_table(journey: JourneyTable, section: int) -> PlanTable:
    """Section `section`'s ato curve as a PlanTable (a view of the journey's grid)."""
    columns = journey.grid[:, journey.bounds[section]:journey.bounds[section + 1]]
    return PlanTable(columns, False, True, True)


@jitable
def departure(journey: JourneyTable, state: JourneyState) -> float:
    """When a train that has arrived at its section's end leaves it, s."""
    return max(journey.departures[state.section],
               state.arrival + journey.dwells[state.section])


@jitable
def journey_speed(journey: JourneyTable, state: JourneyState, t: float, position: float
                  ) -> float:
    """The target at time t with the head at `position` (m along the line), m/s."""
    section = state.section
    if state.arrival == state.arrival:  # standing at the end of its section
        if t < departure(journey, state):
            return 0.0
        section += 1
    return table_speed(section_table(journey, section), position - journey.stops[section])


@jitable
def observed(journey: JourneyTable, state: JourneyState, t: float, position: float,
             speed: float) -> JourneyState:
    """The state at t (step k's time) from the position s_k and the speed over the last
    step, (s_k - s_k-1) / period: the next section once the train may leave; arrived
    once it stands within the berth of its section's end, or past it."""
    if state.arrival == state.arrival:
        if t < departure(journey, state):
            return state
        state = JourneyState(state.section + 1, math.nan)
    end = journey.stops[state.section + 1]
    if abs(speed) < STANDSTILL and position >= end - journey.berth:
        return JourneyState(state.section, t)
    return state


@jitable
def journey_limit(journey: JourneyTable, position: float) -> float:
    """The belt's limit with the head at `position`, m/s: that of the section it is on
    (the first before the journey, the last after it)."""
    section = min(max(cell_of(journey.stops, position), 0), len(journey.stops) - 2)
    return table_limit(section_table(journey, section), position - journey.stops[section])


class JourneyPlan(Plan):
    """The journey's target for one run: the tables and the state `observe` derives
    (a plan per run context: never shared between runs)."""

    position_indexed = True
    shapes_itself = True  # its curves apply profile.envelope_share and profile.jerk
    limits_speed = True   # the curves' belt limits

    def __init__(self, journey: JourneyTable, notice: str | None):
        self.journey, self.notice = journey, notice
        self.state = START

    def observe(self, t: float, position: float, speed: float) -> None:
        """Step k's time, position and speed over the last step in (see `observed`)."""
        self.state = observed(self.journey, self.state, t, position, speed)

    def speed(self, t: float, position: float = 0.0) -> float:
        return float(journey_speed(self.journey, self.state, t, position))

    def limit(self, position: float) -> float:
        return float(journey_limit(self.journey, position))


def journey_table(timetable: Timetable, values, line, train) -> tuple[JourneyTable, str | None]:
    """The sections' ato curves on `line` for `train`, each on time for its running time
    in the timetable less the recovery (with profile.ato.on_time), and the first
    section's notice of a running time it cannot meet."""
    curves, notice = [], None
    for section in timetable.sections:
        own = dataclasses.replace(section_line(line, section.start, section.end),
                                  planned_run_time=section.running_time
                                  - values["profile.journey.recovery"])
        curve = ato_curve(values, own, train)
        curves.append(curve)
        if curve.notice and notice is None:
            notice = f"{section.origin} - {section.destination}: {curve.notice}"
    dwells = {station.name: station.dwell for station in line.stations}
    stops = timetable.stops
    leaving = [stop.departure - stops[0].departure for stop in stops[1:-1]]
    return JourneyTable(
        grid=np.concatenate([curve.table().grid for curve in curves], axis=1),
        bounds=np.cumsum([0] + [len(curve.positions) for curve in curves], dtype=np.int64),
        stops=np.array([stop.position for stop in stops]),
        departures=np.array([*leaving, math.inf]),
        dwells=np.array([dwells[stop.station] for stop in stops[1:]]),
        berth=float(values["profile.journey.berth"])), notice


def _journey(values, context) -> JourneyPlan:
    path = values["profile.journey.timetable"]
    if not path:
        raise ScenarioError("profile.kind is journey but profile.journey.timetable is empty")
    if context.line is None:
        raise ScenarioError("profile.kind is journey but line.file is empty")
    timetable = load_timetable(path)
    if timetable.line != context.line:  # by contents: a bag's copies have other paths
        raise ScenarioError(f"timetable {path} is of line {timetable.line_file}, the run's "
                            f"line.file is {values['line.file']} (their contents differ)")
    if timetable.train != values["plant.train"]:
        raise ScenarioError(f"timetable {path} is planned for train {timetable.train!r}, the "
                            f"run uses {values['plant.train'] or '(none)'!r}")
    first = timetable.stops[0]
    if abs(values["plant.initial_position"] - first.position) > values["profile.journey.berth"]:
        raise ScenarioError(f"timetable {path} starts at {first.station} "
                            f"({first.position:g} m); plant.initial_position is "
                            f"{values['plant.initial_position']:g} m")
    return JourneyPlan(*journey_table(timetable, values, context.line, context.train))


JOURNEY = Component("journey", "a timetable's stops served one after another: each "
                    "section's ato curve, held at each stop until its departure",
                    (*JOURNEY_PARAMETERS, *ATO_PARAMETERS), _journey)
