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

A train that leaves a stop late catches up (profile.journey.catch_up): each section has
faster curves beside its on-time one, and as the train leaves a stop (`leaving`, inside
the state, so the node, simulate() and the compiled loop choose alike) its lateness, its
release less the timetable's departure, picks the slowest that wins it back, else the
fastest (minimum-time); under profile.journey.catch_up_after late it keeps its on-time
curve. Each such re-plan is a Replan (JourneyPlan.replans): the profile node says it on
the run's events topic ('replanned ...') and publishes it for the recorder; `replans`
derives the same from a run's positions. profile.journey.dwell_extension holds the train
longer at given stops (an injected delay).

A TTOBench journey (timetable.journey_timetable: windows at its stops, passing points
between them) is served alike: each section on time for its arrival window's latest time
less the recovery, held until its departure window opens; its curve capped to pass each
passing point inside the point's window (timed_curve), or, where the train cannot with
the arrival kept, said at start-up in the plan's notice.

The tables (JourneyTable) are the sections' curves one after another, read by the same
functions in Python and compiled code (core/run/fast_loop.py), to the same bits.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import NamedTuple

import numpy as np

from ..base.errors import ScenarioError
from ..base.kernels import jitable
from ..base.registry import Component, Plan
from ..base.spec import PROFILE_NODES, TextForm, param
from ..base.units import MS_TO_KMH
from ..train.line import Section, with_speed_restrictions
from ..train.plant import TrainParameters
from . import least_energy
from .profiles import (ATO_PARAMETERS, AtoCurve, Ceiling, DepartureRamp, PlanTable, ato_curve,
                       cell_of, departing, departure_ramp, rows_speed, table_limit)
from .restriction import SPEED_RESTRICTION, restricted_line
from .timetable import JourneySection, PassingPoint, Timetable, load_timetable, section_line

STANDSTILL = 0.01  # m/s: slower over a step counts as standing (a held train does not move)
_EXTENSION = r"\s*\d+\s*:\s*\d+(?:\.\d*)?\s*"
LONGEST_EXTENSION = 3600.0  # s: a dwell extended longer is a service cancelled, not a delay
# m: a journey's train starts standing at its first stop's mark, as a train stopped there
# stands: within the stopping accuracy (scoring's STOP_TOLERANCE). Not the berth (up to
# 100 m): a start that far off puts the train off every section's curve.
AT_ORIGIN = 0.1

DRIVINGS = ("cruise", "least_energy")
JOURNEY_PARAMETERS = (
    param("profile.journey.timetable", "", "timetable file (msg_config/timetables/*.yaml) of "
          "the journey to drive, of the run's line.file and plant.train, or a TTOBench "
          "journey file (.json, msg_config/ttobench/journeys/) on the run's line.file's "
          "track, for any train; relative to the scenario file, else to msg_config/",
          PROFILE_NODES),
    param("profile.journey.berth", 1.0, "a train standing less than this before a stop mark, "
          "or past it, has arrived there and is held until it leaves, m", PROFILE_NODES,
          0.01, 100.0),
    param("profile.journey.recovery", 0.0, "each section's curve is planned this much inside "
          "its running time (with profile.ato.on_time), kept back for what the curve does not "
          "count (the holding brake's release, the tracking's lag); an early train waits for "
          "its departure at the next stop, s", PROFILE_NODES, 0.0, 60.0),
    param("profile.journey.driving", "cruise", "how each section is driven on time: cruise, "
          "the ato curve at the lowest cruise speed that meets its running time; least_energy, "
          "the ato curve kept under the section's least-energy run for the nominal train "
          "(core/targets/least_energy.py: it runs faster and coasts), its top speeds capped "
          "to meet the time", PROFILE_NODES, choices=DRIVINGS),
    param("profile.journey.catch_up", 8, "faster curves planned per section beside its on-time "
          "one (cruise speeds up to the highest, at profile.journey.catch_up_share): a train "
          "that leaves a stop late drives the slowest that wins its lateness back, else the "
          "fastest (minimum-time); 0: a late train keeps its on-time curves", PROFILE_NODES,
          0, 32),
    param("profile.journey.catch_up_share", 0.95, "the faster curves plan with at least this "
          "share of the envelope (with profile.envelope_share > 0; the on-time curve's share "
          "if higher): catching up spends part of the reserve for what the plan does not "
          "know", PROFILE_NODES, 0.05, 1.0),
    param("profile.journey.catch_up_braking", 1.08, "the faster curves' service braking over "
          "the on-time curve's (profile.ato.deceleration): a harder braking wins the most "
          "time; the stop's accuracy on a train heavier than weighed sets how much harder",
          PROFILE_NODES, 1.0, 2.0),
    param("profile.journey.catch_up_after", 1.0, "a train that leaves a stop less late than "
          "this keeps its on-time curve (the first faster curve may win seconds more), s",
          PROFILE_NODES, 0.0, 600.0),
    param("profile.journey.dwell_extension", "", "delays injected: STOP:SECONDS[,STOP:SECONDS"
          "...], the train held SECONDS longer at the timetable's stop number STOP (1 is the "
          f"origin; a crowded platform, a door fault; at most {LONGEST_EXTENSION:g} s at a "
          "stop), s", PROFILE_NODES,
          form=TextForm(rf"\s*|{_EXTENSION}(?:,{_EXTENSION})*",
                        "STOP:SECONDS[,STOP:SECONDS...] (stop numbers from 1, seconds >= 0)")),
)


class JourneyTable(NamedTuple):
    """A journey as the target reads it: section i has `levels` curves, its on-time curve
    (level 0) and faster ones in order; curve l of section i is grid[:, bounds[c]:
    bounds[c + 1]] with c = i * levels + l (positions from the section's start, speeds,
    the belt's limits), its running time times[i, l], the timetable's less the recovery
    scheduled[i] (less than times[i, 0] where a speed restriction makes it unmet). The
    section runs from stops[i] to stops[i + 1] (m along the line); the train may leave
    its end at departures[i] (s, run clock; inf at the last stop), or dwells[i] after it
    arrived there if later, and in either case extensions[i] later
    (profile.journey.dwell_extension)."""

    grid: np.ndarray        # 3 x points
    bounds: np.ndarray      # sections * levels + 1 column indices
    levels: int             # curves per section: 1 + profile.journey.catch_up
    times: np.ndarray       # sections x levels, s
    scheduled: np.ndarray   # sections, s
    stops: np.ndarray       # sections + 1 positions, m
    departures: np.ndarray  # sections, s
    dwells: np.ndarray      # sections, s
    extensions: np.ndarray  # sections, s
    berth: float            # m (profile.journey.berth)
    catch_up_after: float   # s (profile.journey.catch_up_after)
    departure: DepartureRamp  # how the target leaves each stop (profile.departure_jerk)


class JourneyState(NamedTuple):
    """What the profile carries from step to step on a journey."""

    section: int    # the section served: the train is on it or stands at its end
    arrival: float  # s: when the train was found standing at the section's end (NaN: not yet)
    level: int      # the section's curve it drives (0: on time; chosen as it left)
    left: float     # s: when it was released onto the section (its departure ramp's start)


START = JourneyState(0, math.nan, 0, 0.0)  # the first section, from the first departure at t = 0


@jitable(inline=True)
def section_table(journey: JourneyTable, section: int, level: int) -> PlanTable:
    """Curve `level` of section `section` as a PlanTable (a view of the journey's grid)."""
    curve = section * journey.levels + level
    columns = journey.grid[:, journey.bounds[curve]:journey.bounds[curve + 1]]
    return PlanTable(columns, False, True, True)


@jitable(inline=True)
def departure(journey: JourneyTable, state: JourneyState) -> float:
    """When a train that has arrived at its section's end leaves it, s."""
    return max(journey.departures[state.section],
               state.arrival + journey.dwells[state.section]) + journey.extensions[state.section]


@jitable
def catch_up_level(journey: JourneyTable, section: int, lateness: float) -> int:
    """The curve of `section` for a train that leaves its start `lateness` s after the
    timetable: the slowest that wins the lateness back, else the fastest; the on-time
    curve for a train less late than journey.catch_up_after."""
    if lateness < journey.catch_up_after or lateness <= 0.0:
        return 0
    wanted = journey.times[section, 0] - lateness
    for level in range(journey.levels):
        if journey.times[section, level] <= wanted:
            return level
    return journey.levels - 1


@jitable
def lateness(journey: JourneyTable, state: JourneyState) -> float:
    """How late a train that has arrived at its section's end leaves it, against the
    timetable's departure, s."""
    return departure(journey, state) - journey.departures[state.section]


@jitable
def leaving(journey: JourneyTable, state: JourneyState) -> JourneyState:
    """The state of a train as it leaves the end of its section: the next section, on the
    curve its lateness picks (re-planned from the time it is released)."""
    return JourneyState(state.section + 1, math.nan,
                        catch_up_level(journey, state.section + 1, lateness(journey, state)),
                        departure(journey, state))


@jitable(inline=True)
def journey_speed(journey: JourneyTable, state: JourneyState, t: float, position: float
                  ) -> float:
    """The target at time t with the head at `position` (m along the line), m/s."""
    if state.arrival == state.arrival:  # standing at the end of its section
        if t < departure(journey, state):
            return 0.0
        state = leaving(journey, state)
    # the curve's rows read in place: contiguous, unlike section_table's columns
    curve = state.section * journey.levels + state.level
    first, end = journey.bounds[curve], journey.bounds[curve + 1]
    return departing(journey.departure, t - state.left,
                     rows_speed(journey.grid[0, first:end], journey.grid[1, first:end], False,
                                True, position - journey.stops[state.section]))


@jitable
def observed(journey: JourneyTable, state: JourneyState, t: float, position: float,
             speed: float) -> JourneyState:
    """The state at t (step k's time) from the position s_k and the speed over the last
    step, (s_k - s_k-1) / period: the next section once the train may leave; arrived
    once it stands within the berth of its section's end, or past it."""
    if state.arrival == state.arrival:
        if t < departure(journey, state):
            return state
        state = leaving(journey, state)
    end = journey.stops[state.section + 1]
    if abs(speed) < STANDSTILL and position >= end - journey.berth:
        return JourneyState(state.section, t, state.level, state.left)
    return state


@jitable(inline=True)
def journey_limit(journey: JourneyTable, position: float) -> float:
    """The belt's limit with the head at `position`, m/s: that of the section it is on
    (the first before the journey, the last after it)."""
    section = min(max(cell_of(journey.stops, position), 0), len(journey.stops) - 2)
    return table_limit(section_table(journey, section, 0),
                       position - journey.stops[section])


class Replan(NamedTuple):
    """A train that left a stop late and the curve it drives to the next: what the profile
    says on the run's events topic and records in the bag (`replans` derives the same
    from a run's series)."""

    time: float          # s: the step at which it left
    origin: str          # the stop it left
    destination: str
    lateness: float      # s after the timetable's departure
    running_time: float  # s: the chosen curve's, standstill to standstill
    on_time: float       # s: the section's on-time curve's
    scheduled: float     # s: the timetable's less the recovery (on_time unless unmet)
    minimum_time: bool   # the fastest curve, and it does not win the lateness all back

    def text(self) -> str:
        said = (f"{self.origin} - {self.destination}: left {self.lateness:.1f} s late, "
                f"{self.running_time:.1f} s planned instead of {self.on_time:.1f} s")
        if self.minimum_time:
            late = self.lateness + self.running_time - self.scheduled
            said += f"; driving minimum-time, {late:.1f} s late at {self.destination}"
        return said


class JourneyPlan(Plan):
    """The journey's target for one run: the tables, the state `observe` derives and the
    re-plans it made (a plan per run context: never shared between runs)."""

    position_indexed = True
    shapes_itself = True  # its curves apply profile.envelope_share and profile.jerk
    limits_speed = True   # the curves' belt limits

    def __init__(self, journey: JourneyTable, notice: str | None, stations: tuple[str, ...]):
        self.journey, self.notice, self.stations = journey, notice, stations
        self.state = START
        self.replans: list[Replan] = []

    def observe(self, t: float, position: float, speed: float) -> None:
        """Step k's time, position and speed over the last step in (see `observed`)."""
        self.moved(t, observed(self.journey, self.state, t, position, speed))

    def moved(self, t: float, state: JourneyState) -> None:
        """The state `observed` gave at t; a re-plan made when the train left late."""
        before, self.state = self.state, state
        if self.state.section != before.section and self.state.level > 0:  # left late
            self.replans.append(self._replan(t, lateness(self.journey, before)))

    def _replan(self, t: float, lateness: float) -> Replan:
        section, level, times = self.state.section, self.state.level, self.journey.times
        # minimum-time when the chosen curve (the fastest then) does not win it all back
        return Replan(t, self.stations[section], self.stations[section + 1], float(lateness),
                      float(times[section, level]), float(times[section, 0]),
                      float(self.journey.scheduled[section]),
                      bool(times[section, level] > self.journey.scheduled[section] - lateness))

    @property
    def journey_end(self) -> float:
        """Where a train standing has arrived at the last stop, m (as `observed` counts)."""
        return float(self.journey.stops[-1] - self.journey.berth)

    def speed(self, t: float, position: float = 0.0) -> float:
        return float(journey_speed(self.journey, self.state, t, position))

    def limit(self, position: float) -> float:
        return float(journey_limit(self.journey, position))


def replans(plan: JourneyPlan, period: float, position: np.ndarray) -> list[Replan]:
    """The re-plans of a run from its positions (s_k at t_k = k * period), as its profile
    made them: a fresh copy of the run's plan observes each step as the profile node does."""
    copy = JourneyPlan(plan.journey, plan.notice, plan.stations)
    for k, travelled in enumerate(np.diff(position, prepend=position[:1])):
        copy.observe(k * period, float(position[k]), float(travelled) / period)
    return copy.replans


def catch_up_curves(on_time: AtoCurve, fastest: AtoCurve, levels: int, slowest: float
                    ) -> tuple[list[np.ndarray], list[float]]:
    """A section's on-time curve and levels - 1 faster ones, and their running times: the
    `fastest` curve's shape (its share) at cruise speeds from `slowest` (the on-time cruise
    curve's) up to its highest, evenly spaced in 1 / cruise (what a cruise's time goes
    with)."""
    cruises = 1.0 / np.linspace(1.0 / slowest, 1.0 / fastest.cruise, levels)[1:]
    faster = [fastest.curve(cruise) for cruise in cruises]
    return ([on_time.speeds, *faster],
            [on_time.planned_run_time, *(fastest.time_of(speeds) for speeds in faster)])


# What a journey's tables are built from besides its timetable, line and train: its
# parameters, the ato curve's and the shared ones the curves read (new_journey_table reads
# the values of these alone, so a value it would read besides fails loudly, uncached).
TABLE_INPUTS = tuple(sorted({*(spec.name for spec in (*JOURNEY_PARAMETERS, SPEED_RESTRICTION,
                                                      *ATO_PARAMETERS)),
                             "profile.envelope_share", "profile.jerk", "profile.departure_jerk",
                             "plant.length"}))


def journey_table(timetable: Timetable, values, line, train, nominal=None
                  ) -> tuple[JourneyTable, str | None]:
    """new_journey_table, once per process for each distinct timetable, line, train, nominal
    train (all compared by their contents) and TABLE_INPUTS values: the plan a run's validation
    built is the one its simulation reads, and so are a tuning's candidates' (their gains
    are not its inputs). Never changed by a caller (JourneyPlan only reads it)."""
    return _journey_tables(timetable, line, train, nominal or train,
                           tuple((name, values[name]) for name in TABLE_INPUTS))


# A long journey's tables are tens of MB (seed002-journey's 61 MB: 3 sections x 9 curves
# x 10^5 cells): two kept, enough for a run's validation and simulation, a tuning's runs.
@functools.lru_cache(maxsize=2)
def _journey_tables(timetable: Timetable, line, train, nominal, inputs: tuple
                    ) -> tuple[JourneyTable, str | None]:
    return new_journey_table(timetable, dict(inputs), line, train, nominal)


def new_journey_table(timetable: Timetable, values, line, train, nominal=None
                      ) -> tuple[JourneyTable, str | None]:
    """The sections' ato curves on `line` for `train`, each on time for its running time
    in the timetable less the recovery (with profile.ato.on_time; driven as
    profile.journey.driving says, least_energy under the runs planned for the `nominal`
    train, `train` if None) and its faster curves (profile.journey.catch_up), under the
    run's speed restrictions (profile.journey.speed_restriction); and the notices of the
    running times they cannot meet, in one line."""
    levels = 1 + values["profile.journey.catch_up"]
    line = restricted_line(values, line)
    curves, times, notices = [], [], []
    scheduled = [section.running_time - values["profile.journey.recovery"]
                 for section in timetable.sections]
    for section, planned, stop in zip(timetable.sections, scheduled, timetable.stops,
                                      strict=False):
        own = dataclasses.replace(section_line(line, section.start, section.end),
                                  planned_run_time=planned)
        ceilings = (least_energy.ceilings(values, own, nominal or train)
                    if values["profile.journey.driving"] == "least_energy" else (None,))
        curve, said = timed_curve(values, own, train, section, stop.departure, ceilings)
        if curve.notice:
            notices.append(f"{section.origin} - {section.destination}: {curve.notice}")
        notices += [f"{section.origin} - {section.destination}: {text}" for text in said]
        # a least-energy curve's faster ones start from the cruise curve of its time: its
        # own cap is its run's top speed, whose cruise curve would win back far more
        slowest = curve.cruise if curve.ceiling is None else ato_curve(values, own,
                                                                        train).cruise
        speeds, section_times = (
            catch_up_curves(curve, fastest_curve(values, own, train), levels, slowest)
            if levels > 1 else ([curve.speeds], [curve.planned_run_time]))
        curves += [(curve.positions, level, curve.limits) for level in speeds]
        times.append(section_times)
    stops = timetable.stops
    leaving_at = [stop.departure - stops[0].departure for stop in stops[1:-1]]
    bounds = np.cumsum([0] + [len(positions) for positions, _, _ in curves], dtype=np.int64)
    return JourneyTable(
        grid=stacked(curves, bounds), bounds=bounds, levels=levels, times=np.array(times),
        scheduled=np.array(scheduled),
        stops=np.array([stop.position for stop in stops]),
        departures=np.array([*leaving_at, math.inf]),
        dwells=np.array([stop.least_dwell for stop in stops[1:]]),
        extensions=dwell_extensions(values["profile.journey.dwell_extension"], timetable),
        berth=float(values["profile.journey.berth"]),
        catch_up_after=float(values["profile.journey.catch_up_after"]),
        departure=departure_ramp(values, train, values["profile.ato.start_speed"])), \
        " | ".join(notices) or None


def timed_curve(values, line, train, section: JourneySection, departure: float,
                ceilings: tuple[Ceiling | None, ...] = (None,)) -> tuple[AtoCurve, list[str]]:
    """The section's on-time curve on `line` (its own, planned to its running time; kept
    under the first of `ceilings` that meets that time and, at its fastest, passes no
    passing point after its window, else the last) kept to its passing points' windows
    (passing_window), each in turn: a curve that passes a point too late is capped after
    it, one too early before it, at the cruise that passes it at the window's nearer edge
    (the least change from the on-time curve, which a cruise curve's energy favours); and
    what cannot be kept, in one line each: a window the curve cannot meet together with
    the arrival, a speed bound it breaks."""
    ceiling = ceilings[-1]
    for candidate in ceilings[:-1]:
        fastest = least_energy.curve_of(values, line, train, candidate)
        if not ato_curve(values, line, train, candidate).notice and not any(
                fastest.passing_time(point.position - section.start)
                > passing_window(point, departure, values["profile.journey.recovery"])[1]
                for point in section.passing):
            ceiling = candidate
            break
    curve, said, caps = ato_curve(values, line, train, ceiling), [], ()
    for point in section.passing:
        if curve.notice:  # not even the arrival is met: no window to keep besides
            break
        low, high = passing_window(point, departure, values["profile.journey.recovery"])
        at = point.position - section.start
        passes = curve.passing_time(at)
        if low <= passes <= high:
            continue
        late = passes > high
        capped = _capped_at(values, line, train, ceiling, caps, at, high if late else low,
                            late)
        if capped is None:
            said.append(f"{point.name}: the window {point.window.text()} cannot be "
                        f"met with the arrival by this train (planned at "
                        f"{departure + passes:.1f} s); passing it as the on-time curve does")
            continue
        curve, caps = capped
    return curve, said + _speed_bounds(curve, section, values)


def passing_window(point: PassingPoint, departure: float, recovery: float
                   ) -> tuple[float, float]:
    """When the head should pass `point`, s after the section's `departure`: its window
    kept `recovery` inside either edge set (its middle when narrower), -inf/inf unset."""
    low = -math.inf if point.window.earliest is None else point.window.earliest - departure
    high = math.inf if point.window.latest is None else point.window.latest - departure
    if high - low < 2.0 * recovery:
        return (low + high) / 2.0, (low + high) / 2.0
    return low + recovery, high - recovery


CAP_STEPS = 24  # bisections of a passing point's cap: the cruise to ~1e-7 of its range


def _capped_at(values, line, train, ceiling: Ceiling | None, caps: tuple, at: float,
               wanted: float, late: bool) -> tuple[AtoCurve, tuple] | None:
    """The on-time curve passing `at` (m) at `wanted` (s after the departure), the line
    capped after `at` (a curve that passed `late`) or before it (early) at the cruise
    bisected for it, with the caps `caps` already set; None when no cap does it and
    still arrives on time."""
    def capped(cap: float) -> tuple[AtoCurve, tuple]:
        stretch = Section(at, line.stop_position, cap) if late else Section(0.0, at, cap)
        limits = (*caps, stretch)
        return ato_curve(values, with_speed_restrictions(line, limits), train, ceiling), limits

    low, high = values["profile.ato.start_speed"] + values["profile.ato.margin"], \
        max(section.value for section in line.speed_limits)
    for _ in range(CAP_STEPS):
        middle = 0.5 * (low + high)
        curve, _limits = capped(middle)
        # a lower cap after the point passes it earlier; before it, later
        if (curve.passing_time(at) > wanted) == late:
            high = middle
        else:
            low = middle
    found = capped(low)  # the side that passes within the window
    passes = found[0].passing_time(at)
    met = passes <= wanted + CAP_TOLERANCE if late else passes >= wanted - CAP_TOLERANCE
    return found if met and not found[0].notice else None


CAP_TOLERANCE = 0.5  # s a capped curve may pass beyond the window it was bisected to


def _speed_bounds(curve: AtoCurve, section: JourneySection, values) -> list[str]:
    """A notice for each passing point whose speed bounds the curve breaks."""
    said = []
    for point in section.passing:
        speed = float(np.interp(point.position - section.start, curve.positions, curve.speeds))
        if point.min_speed is not None and speed < point.min_speed:
            said.append(f"{point.name}: passed at {speed * MS_TO_KMH:.1f} km/h, below its "
                        f"lower speed bound {point.min_speed * MS_TO_KMH:g} km/h")
        if point.max_speed is not None and speed > point.max_speed:
            said.append(f"{point.name}: passed at {speed * MS_TO_KMH:.1f} km/h, above its "
                        f"upper speed bound {point.max_speed * MS_TO_KMH:g} km/h")
    return said


def stacked(curves: list[tuple], bounds: np.ndarray) -> np.ndarray:
    """The rows (positions, speeds, limits) of each curve one after another, curve c in
    columns bounds[c]:bounds[c + 1] (written once: a long journey's are tens of MB)."""
    grid = np.empty((3, bounds[-1]))
    for c, rows in enumerate(curves):
        for row, values in enumerate(rows):
            grid[row, bounds[c]:bounds[c + 1]] = values
    return grid


def fastest_curve(values, line, train) -> AtoCurve:
    """The section's ato curve at its highest cruise, its catch-up share of the envelope and
    braking (no time to meet: no bisection), its time counted as the on-time one's."""
    share = values["profile.envelope_share"]
    faster = {**values, "profile.envelope_share": share and max(
                  share, values["profile.journey.catch_up_share"]),
              "profile.ato.deceleration": values["profile.ato.deceleration"]
              * values["profile.journey.catch_up_braking"]}
    return ato_curve(faster, dataclasses.replace(line, planned_run_time=None), train)


def dwell_extensions(text: str, timetable: Timetable) -> np.ndarray:
    """profile.journey.dwell_extension (STOP:SECONDS, ...) as the s added to the hold at
    each section's end; ScenarioError for a stop that is not between the journey's ends
    or more than LONGEST_EXTENSION s at one."""
    extensions = np.zeros(len(timetable.sections))
    for item in filter(None, (part.strip() for part in text.split(","))):
        number, seconds = (int(item.split(":")[0]), float(item.split(":")[1]))
        if not 2 <= number <= len(timetable.stops) - 1:
            raise ScenarioError(f"profile.journey.dwell_extension: stop {number} is not a stop "
                                f"between the ends of {timetable.path} (2 to "
                                f"{len(timetable.stops) - 1})")
        total = extensions[number - 2] + seconds
        if total > LONGEST_EXTENSION:
            raise ScenarioError(f"profile.journey.dwell_extension: {total:g} s at stop {number} "
                                f"is more than {LONGEST_EXTENSION:g} s")
        extensions[number - 2] = total
    return extensions


def _journey(values, context) -> JourneyPlan:
    path = values["profile.journey.timetable"]
    if not path:
        raise ScenarioError("profile.kind is journey but profile.journey.timetable is empty")
    if context.line is None:
        raise ScenarioError("profile.kind is journey but line.file is empty")
    timetable = load_timetable(path)
    if not timetable.on_line(context.line, values):  # by contents: a bag copy has another path
        raise ScenarioError(f"timetable {path} is of line {timetable.line_file}, the run's "
                            f"line.file is {values['line.file']} (their contents differ)")
    if not timetable.for_train(values["plant.train"]):
        raise ScenarioError(f"timetable {path} is planned for train {timetable.train!r}, the "
                            f"run uses {values['plant.train'] or '(none)'!r}")
    first = timetable.stops[0]
    if abs(values["plant.initial_position"] - first.position) > AT_ORIGIN:
        raise ScenarioError(f"timetable {path} starts at {first.station} "
                            f"({first.position:g} m); plant.initial_position is "
                            f"{values['plant.initial_position']:g} m (at most {AT_ORIGIN:g} m "
                            f"from it)")
    return JourneyPlan(*journey_table(timetable, values, context.line, context.plan_train,
                                      TrainParameters.from_values(values)),
                       tuple(stop.station for stop in timetable.stops))


JOURNEY = Component("journey", "a timetable's stops served one after another: each "
                    "section's ato curve, held at each stop until its departure",
                    (*JOURNEY_PARAMETERS, SPEED_RESTRICTION, *ATO_PARAMETERS), _journey)
