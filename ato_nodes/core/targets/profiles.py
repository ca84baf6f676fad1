"""Target-speed profiles, ROS-free. Every profile maps (time, position) to m/s."""

from __future__ import annotations

import csv
import functools
import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..base.errors import ScenarioError
from ..base.kernels import compiled, jitable
from ..base.registry import Component, Plan
from ..base.spec import MAX_PREVIEW, PROFILE_NODES, param
from ..base.units import KMH
from ..train.line import Line
from ..train.plant import TrainParameters, basic_resistance, force_limits
from .curve_passes import (ROUNDING_WIDTH, CurveGrid, capped_curve, cell_times, forward_pass,
                           interpolated_in, round_corners, rounded_curve, running_time,
                           shaped_curve, sloped)

SEED000_PARAMETERS = (
    param("profile.seed000.cycle", 1200.0, "T of eq. 25, s", PROFILE_NODES, 1.0, 1e6),
    param("profile.seed000.v_inc", 368.34 * KMH, "Vinc of eq. 25, m/s", PROFILE_NODES, 0.0, 300.0),
    param("profile.seed000.t1", 125.2841, "t1 of eq. 25, s", PROFILE_NODES, 0.0, 1e6),
    param("profile.seed000.cruise_high", 350.0 * KMH, "upper cruise speed, m/s", PROFILE_NODES,
          0.0, 300.0),
    param("profile.seed000.cruise_low", 200.0 * KMH, "lower cruise speed, m/s", PROFILE_NODES,
          0.0, 300.0),
)


class PlanTable(NamedTuple):
    """A position-indexed plan as compiled code reads it: the speed interpolated in the
    values against the positions (values are speeds, or squared speeds when `squared`),
    0 from the last position on when `stops_at_end`; the plan's own limit per cell of the
    positions when `limits_speed` (Plan.limits_speed). One array, because compiled code
    pays for every array it hands to a function."""

    grid: np.ndarray       # rows: positions (m, increasing), values, limits (m/s)
    squared: bool
    stops_at_end: bool
    limits_speed: bool


def plan_table(positions, values, squared: bool = False, stops_at_end: bool = False,
               limits=None) -> PlanTable:
    """A PlanTable (limits: None, the line's apply)."""
    grid = np.empty((3, len(positions)))
    grid[0], grid[1] = positions, values
    grid[2] = limits if limits is not None else np.nan
    return PlanTable(grid, squared, stops_at_end, limits is not None)


@jitable
def table_speed(table: PlanTable, position: float) -> float:
    """The plan's speed at `position`, m/s (as the plan's speed() gives it)."""
    return rows_speed(table.grid[0], table.grid[1], table.squared, table.stops_at_end,
                      position)


@jitable(inline=True)
def rows_speed(positions, values, squared: bool, stops_at_end: bool, position: float
               ) -> float:
    """table_speed of a table's rows (a journey's curve reads its rows in place)."""
    if stops_at_end and position >= positions[len(positions) - 1]:
        return 0.0
    value = interpolated(position, positions, values)
    return math.sqrt(max(0.0, value)) if squared else value


@jitable
def table_limit(table: PlanTable, position: float) -> float:
    """The plan's own limit with the head at `position`, m/s (AtoCurve.limit)."""
    positions = table.grid[0]
    cell = cell_of(positions, position)
    return table.grid[2, min(max(cell, 0), len(positions) - 1)]


@jitable(inline=True)
def cell_of(points, x: float) -> int:
    """The i with points[i] <= x < points[i + 1] (-1 before the first, the last index from
    the last on): np.searchsorted(points, x, side="right") - 1, for increasing points."""
    if not x >= points[0]:
        return -1
    last = len(points) - 1
    if x >= points[last]:
        return last
    low, high = 0, last
    # First around the cell x falls in if the points are evenly spaced (an ATO curve's are:
    # x is in that cell or a neighbour), then by halving as long as it takes.
    guess = min(int((x - points[0]) / (points[last] - points[0]) * last), last - 1)
    if points[max(guess - 1, 0)] <= x:
        low = max(guess - 1, 0)
    if x < points[min(guess + 2, last)]:
        high = min(guess + 2, last)
    while high - low > 1:  # points[low] <= x < points[high]
        middle = (low + high) // 2
        if points[middle] <= x:
            low = middle
        else:
            high = middle
    return low


@jitable(inline=True)
def interpolated(x: float, points, values) -> float:
    """np.interp(x, points, values) for one x and strictly increasing points, computed as
    numpy's C code computes it (the same bits): numba's np.interp allocates arrays on
    every call, ten times the cost of the arithmetic in a compiled loop."""
    if x != x:  # NaN: numpy returns it as it is
        return x
    last = len(points) - 1
    if x >= points[last]:
        return values[last]
    if x < points[0]:
        return values[0]
    j = cell_of(points, x)
    x0, x1, y0, y1 = points[j], points[j + 1], values[j], values[j + 1]
    return interpolated_in(x, x0, x1, y0, y1, sloped(x0, x1, y0, y1))


@dataclass(frozen=True)
class Seed000Profile(Plan):
    """Seed 000 eq. 25 as reconstructed in docs/papers.md (constants in SI; the
    defaults are in SEED000_PARAMETERS).

    Start - cruise - decelerate - cruise - accelerate - cruise - decelerate -
    stop over 2T. The 200 km/h and 0 bounds of the second and fourth pieces
    follow from continuity (the extracted text prints 350 for all four).
    """

    cycle: float         # T, s
    v_inc: float         # m/s
    t1: float            # s
    cruise_high: float   # m/s
    cruise_low: float    # m/s
    position_indexed = False

    def speed(self, t: float, position: float = 0.0) -> float:
        T, v = self.cycle, self.v_inc
        if t < T / 2:
            return min(v * (1.0 - math.exp(-t / 120.0)), self.cruise_high)
        if t < T:
            return max(v * (1.0 - math.exp(-(T / 2 + 240.0 - t) / 80.0)), self.cruise_low)
        if t < 3 * T / 2:
            return min(v * (1.0 - math.exp(-(t - T + self.t1) / 160.0)), self.cruise_high)
        return max(v * (1.0 - math.exp(-(3 * T / 2 + 480.0 - t) / 160.0)), 0.0)


@functools.lru_cache(maxsize=8)
def feasible_plan(plan, train: TrainParameters, share: float, jerk: float, period: float,
                  steps: int) -> FeasiblePlan:
    """One FeasiblePlan per distinct plan and train (its passes cost about a second for a
    2400 s run; every tuning candidate and robustness sample of the plan shares it, and a
    FeasiblePlan is never changed once built)."""
    return FeasiblePlan(plan, train, share, jerk, period, steps)


class FeasiblePlan(Plan):
    """A time-indexed plan made drivable by the nominal train (profile.envelope_share,
    profile.jerk), precomputed on the run's step grid: where the plan asks more
    traction or braking force than `share` of the envelope against the basic
    resistance, the target falls behind it and catches up as the share allows
    (forward then backward pass; braking starts earlier, so the target is never above
    what the train can brake from); then its corners are rounded to `jerk` over
    T = (the largest planned acceleration change) / jerk. Between steps, linear."""

    position_indexed = False

    def __init__(self, plan, train: TrainParameters, share: float, jerk: float, period: float,
                 steps: int):
        self.period = period
        times = period * np.arange(steps + 2 * MAX_PREVIEW)
        raw = np.array([plan.speed(t) for t in times])
        speeds = raw.copy()
        if share > 0.0:
            xi = train.xi
            for k in range(len(speeds) - 1):  # forward: the acceleration it can give
                v = speeds[k]
                reach = v + period * xi * train.net_traction(v, share)
                speeds[k + 1] = min(speeds[k + 1], max(reach, 0.0))
            for k in range(len(speeds) - 2, -1, -1):  # backward: the braking it can give
                v = speeds[k + 1]
                reach = v + period * xi * train.net_braking(v, share)
                speeds[k] = min(speeds[k], reach)
        if jerk > 0.0:
            acceleration = np.diff(speeds) / period
            change = float(np.max(np.abs(np.diff(acceleration)))) if len(acceleration) > 1 else 0.0
            width = max(2, 2 * round(change / jerk / period / 2))
            speeds = round_corners(speeds, width, speeds[-1])
        self.speeds = speeds.tolist()

    def speed(self, t: float, position: float = 0.0) -> float:
        x = t / self.period
        i = min(max(int(x), 0), len(self.speeds) - 2)
        low = self.speeds[i]
        return low + (min(x, i + 1.0) - i) * (self.speeds[i + 1] - low)


@dataclass(frozen=True)
class StepProfile(Plan):
    """Zero before `time`, `speed` from then on (seed 000's step-response test)."""

    speed_after: float
    time: float
    position_indexed = False

    def speed(self, t: float, position: float = 0.0) -> float:
        return self.speed_after if t >= self.time else 0.0


class TableProfile(Plan):
    """Piecewise-linear speed against time or position, read from a CSV table.

    The CSV has a header naming its two columns: `time` (s) or `position` (m),
    then `speed` (m/s). Beyond the table the end values hold.
    """

    def __init__(self, axis: str, points: np.ndarray, speeds: np.ndarray):
        if axis not in ("time", "position"):
            raise ValueError(f"profile axis must be 'time' or 'position', not {axis!r}")
        if len(points) < 2 or np.any(np.diff(points) <= 0):
            raise ValueError("profile table needs at least two rows with strictly increasing "
                             f"{axis}")
        if np.any(speeds < 0) or not np.all(np.isfinite(speeds)):
            raise ValueError("profile table speeds must be finite and non-negative")
        self.axis = axis
        self.position_indexed = axis == "position"
        self.points = [float(x) for x in points]
        self.speeds = [float(x) for x in speeds]

    @classmethod
    def from_csv(cls, path: str | Path) -> TableProfile:
        path = Path(path)
        try:
            with path.open(newline="") as handle:
                rows = [row for row in csv.reader(handle) if row and not row[0].startswith("#")]
        except OSError as exc:
            raise ValueError(f"cannot read profile table {path}: {exc.strerror}") from None
        if not rows or len(rows[0]) != 2 or rows[0][1].strip() != "speed":
            raise ValueError(f"{path}: header must be 'time,speed' or 'position,speed'")
        try:
            data = np.array([[float(a), float(b)] for a, b in rows[1:]])
        except ValueError:
            raise ValueError(f"{path}: every row after the header needs two numbers") from None
        try:
            return cls(rows[0][0].strip(), data[:, 0], data[:, 1])
        except (ValueError, IndexError) as exc:
            raise ValueError(f"{path}: {exc}") from None

    def speed(self, t: float, position: float = 0.0) -> float:
        x = t if self.axis == "time" else position
        return float(np.interp(x, self.points, self.speeds))

    def table(self) -> PlanTable | None:
        return self._table if self.position_indexed else None

    @functools.cached_property
    def _table(self) -> PlanTable:  # built once: simulate() asks for it twice per run
        return plan_table(self.points, self.speeds)


class StrategyProfile(Plan):
    """A driving strategy (seed 002, scripts/optimize_strategy.py) as the target: its
    speed against distance, interpolated in v^2 (kinetic energy is what a held force
    changes linearly along the track), at least `start_speed` at the departure point
    (a position-indexed target of 0 would never start the train). The strategy's mode
    (1 traction, 0 cruise/coast, -1 brake) and planned force (N/kN) at a position are
    there for a controller's feedforward: context.plan.mode(s), context.plan.force(s)."""

    position_indexed = True

    def __init__(self, plan, start_speed: float):
        self.positions = plan.positions
        energies = plan.speeds ** 2
        energies[0] = max(energies[0], start_speed ** 2)
        self.energies = energies
        self.modes, self.forces = plan.modes, plan.forces

    def speed(self, t: float, position: float = 0.0) -> float:
        return math.sqrt(max(0.0, float(np.interp(position, self.positions, self.energies))))

    def table(self) -> PlanTable:
        return self._table

    @functools.cached_property
    def _table(self) -> PlanTable:  # built once: simulate() asks for it twice per run
        return plan_table(self.positions, self.energies, squared=True)

    def _stage(self, position: float) -> int:
        index = int(np.searchsorted(self.positions, position, side="right")) - 1
        return min(max(index, 0), len(self.positions) - 1)

    def mode(self, position: float) -> int:
        return int(self.modes[self._stage(position)])

    def force(self, position: float) -> float:
        return float(self.forces[self._stage(position)])


class Cells(NamedTuple):
    """What the ato curve's passes know of each grid cell, kept for the capped curves:
    whether it is powered (the pantograph outside every neutral section), its line
    resistance (N/kN), the cells where a neutral section starts; the train and the
    envelope share planned with."""

    powered: np.ndarray
    line_resistance: np.ndarray
    neutral_entries: np.ndarray
    train: TrainParameters
    share: float


class Ceiling(NamedTuple):
    """A speed profile an ato curve keeps under besides the limits: a run to follow (its
    coasting), its squares read between its points linearly (a constant force's); tuples,
    so a curve's cache can key on it."""

    positions: tuple[float, ...]  # m from the curve's departure point, increasing
    speeds: tuple[float, ...]     # m/s


class AtoCurve(Plan):
    """Distance-indexed ATO target curve of one interstation run (seed 004).

    On a grid of `resolution` m from the departure point to the line's stop
    mark, the target is the lowest of: the line limit less `margin` (a raised
    limit counts only once the train's tail has passed the change), a cruise
    speed, the acceleration curve from the departure point and the braking
    curve to every lower limit ahead and to the stop. In v^2 both curves are
    running minima (v^2 grows by at most 2 a dx per cell), so the whole curve
    is a few numpy passes. The cruise speed is the lowest that meets the
    line's planned run time (bisection); when even the limits cannot meet the
    plan, the curve runs at the limits. The departure point's target is
    `start_speed`, not 0, or a position-indexed curve would never start the train.

    Two additions, off by default (the papers' curves):
    * `envelope_share` > 0 with the nominal `train`: the planned traction and braking
      force never exceeds that share of the train's envelope at the speed, against its
      basic and the line's resistance, so the controller keeps the rest for what the
      plan does not know (a steep up grade lowers the target instead of leaving it
      unreachable; a speed the share cannot hold is not planned; in a neutral section
      the plan coasts, and on for `neutral_runout` m after the pantograph has left it:
      traction commanded only once it has left, ladrc.neutral_cut, comes back through
      the actuator's dead time and lag). The passes then step cell by cell; the curve
      for a cruise speed c is the curve without one, capped at c (both passes are
      monotone in their start), except where the share cannot hold c (a neutral
      section, a grade too steep for the weighed train at c): there the curve falls
      from c as the forward pass does, until back on the cap; the rounded curve is held
      to the coasting in neutral sections too (its centred mean would start the
      coasting inside the section).
    * `jerk` > 0: the acceleration changes at most at this jerk, a traction turning
      straight into braking included: the curve in time averaged over T =
      max(acceleration, deceleration) / jerk, centred where it falls (the braking
      starts T/2 earlier, never later), over the past where it rises (the acceleration
      starts later, never earlier), and around each turn from traction straight into
      braking that averaged again, centred, over W = (acceleration + deceleration) /
      jerk (_rounded says why). Where a braking ends at a lower limit the centred mean
      passes over the corner by at most da T / 8 (0.12 m/s for 0.7 m/s^2 at 0.5
      m/s^3); the rounded curve is kept half the margin under the limits, never
      clipped to the cap (a clip would bring the corner back). The eased stop is
      round_corners' alone.

    The running time bisected on is the curve's own time (its rounding and its share
    included) from start_speed at the departure point to the mark. With `departure`
    (s, profile.ato.on_time) it counts from standstill to standstill, as the line's
    planned time does: `departure` before the curve (what the train takes to reach
    start_speed: its dead time, actuator lag and the rounded start) and the eased stop's
    last cell as the easing takes it (v = j t^2 / 2 covers d = v t / 3: 3 d / v, where
    the trapezoid says 2 d / v). A planned time even the fastest curve misses by more
    than LATE_NOTICE is said in `notice` (one line); the curve then runs at the limits.
    """

    position_indexed = True
    shapes_itself = True  # applies profile.envelope_share and profile.jerk in distance
    limits_speed = True  # the belt's limits, with the tail rule (limit())

    def __init__(self, line, acceleration: float, deceleration: float, margin: float = 0.0,
                 start_speed: float = 0.3, train_length: float = 0.0, resolution: float = 0.5,
                 power_speed: float = math.inf, stop_jerk: float = 0.0,
                 train: TrainParameters | None = None, envelope_share: float = 0.0,
                 jerk: float = 0.0, departure: float | None = None,
                 neutral_runout: float = 0.0, ceiling: Ceiling | None = None,
                 floor: float | None = None):
        self.line = line
        self.neutral_runout = neutral_runout
        stop = line.stop_position
        self.positions = np.arange(0.0, stop + resolution / 2, resolution)
        self.positions[-1] = stop
        self.limits = self._belt_limits(self.positions, line, train_length)
        self.acceleration, self.deceleration = acceleration, deceleration
        self.power_speed, self.stop_jerk = power_speed, stop_jerk
        self.start_speed, self.ceiling = start_speed, ceiling
        caps = self.limits - margin
        if ceiling is not None:  # a run to keep under besides the limits (least_energy.py)
            squared = np.interp(self.positions, ceiling.positions, np.square(ceiling.speeds))
            caps = np.minimum(caps, np.sqrt(squared))
        if floor is None:
            self.caps = np.maximum(caps, start_speed)
        else:  # a curve from a running train (a re-plan): the limits ahead still brake it
            self.caps = np.maximum(caps, floor)
            self.caps[0] = max(self.caps[0], start_speed)
        self.margin, self.jerk, self.departure = margin, jerk, departure
        self.cells: Cells | None = None  # set by _feasible
        self.feasible = (self._feasible(train, envelope_share, train_length)
                         if envelope_share > 0.0 else None)
        self.cruise, self.notice, self.speeds, self.planned_run_time = self._cruise(
            float(self.caps.max()), envelope_share)

    def _cruise(self, top: float, share: float) -> tuple[float, str | None, np.ndarray, float]:
        """The lowest cruise speed that meets the line's planned time (bisection), or
        `top` when even that misses it; the notice of a planned time missed; the curve at
        that cruise speed and its running time (each cruise speed's computed once)."""
        planned, curve = self.line.planned_run_time, self.curve(top)
        fastest = self.time_of(curve)
        if planned is None or fastest >= planned:
            notice = None
            if planned is not None and self.departure is not None \
                    and fastest > planned + LATE_NOTICE:
                notice = (f"the line's planned running time {planned:g} s cannot be met: the "
                          f"fastest ato curve (profile.ato.acceleration {self.acceleration:g} "
                          f"m/s^2, profile.envelope_share {share:g}) takes {fastest:.1f} s; "
                          f"driving minimum-time")
            return top, notice, curve, fastest
        low, high = self.start_speed, top
        times = {top: fastest}  # once the interval stops shrinking, middle is low or high
        for _ in range(60):
            middle = 0.5 * (low + high)
            if middle not in times:
                speeds = self.curve(middle)
                times[middle] = self.time_of(speeds)
                if times[middle] <= planned:  # the new high
                    curve = speeds
            low, high = (middle, high) if times[middle] > planned else (low, middle)
        return high, None, curve, times[high]

    @staticmethod
    def _belt_limits(x: np.ndarray, line, train_length: float) -> np.ndarray:
        limits = np.full_like(x, np.inf)
        for section in line.speed_limits:
            inside = (x >= section.start) & (x < section.end + train_length)
            limits[inside] = np.minimum(limits[inside], section.value)
        limits[~np.isfinite(limits)] = line.speed_limits[-1].value
        return limits

    def run_up(self, speed: np.ndarray) -> np.ndarray:
        """Distance the planned acceleration needs from standstill to `speed`: a up to
        power_speed v_p, then a v_p / v (constant power)."""
        a, vp = self.acceleration, self.power_speed
        low = speed * speed / (2.0 * a)
        if not math.isfinite(vp):
            return low
        return np.where(speed <= vp, low,
                        vp * vp / (2.0 * a) + (speed ** 3 - vp ** 3) / (3.0 * a * vp))

    def run_up_speed(self, distance: np.ndarray) -> np.ndarray:
        """The inverse of run_up."""
        a, vp = self.acceleration, self.power_speed
        low = np.sqrt(2.0 * a * distance)
        if not math.isfinite(vp):
            return low
        knee = vp * vp / (2.0 * a)
        return np.where(distance <= knee, low,
                        np.cbrt(vp ** 3 + 3.0 * a * vp * np.maximum(distance - knee, 0.0)))

    def curve(self, cruise: float) -> np.ndarray:
        """The target at every grid point for a cruise speed, m/s (curve_passes: the
        feasible curve capped at the cruise speed where the share can hold it, falling
        from it as the forward pass does where it cannot, until back on the cap; rounded,
        then held to the coasting from each neutral section's start)."""
        if self.feasible is None:
            speeds = self._fixed_rates(cruise)
            return self._rounded(speeds) if self.jerk > 0.0 else speeds
        if self.jerk <= 0.0:
            return capped_curve(self.grid, cruise)
        return shaped_curve(self.grid, cruise, *self._rounding)

    @functools.cached_property
    def grid(self) -> CurveGrid:
        """What the passes of the capped curves read (the curve with a share only)."""
        cells, train = self.cells, self.cells.train
        return CurveGrid(self.positions, self.feasible, cells.powered, cells.line_resistance,
                         cells.neutral_entries, self.limits - self.margin / 2,
                         self._stop_curve, train.envelope, train.davis_a, train.davis_b,
                         train.davis_c, train.xi, cells.share, self.acceleration,
                         self.deceleration, self.power_speed, self.start_speed ** 2)

    @functools.cached_property
    def _rounding(self) -> tuple[float, int]:
        """(tick, width) of _rounded: the tick of the curve in time, s (ROUNDING_WIDTH of
        them over T), and W in ticks, odd."""
        tick = max(self.acceleration, self.deceleration) / self.jerk / ROUNDING_WIDTH
        return tick, 2 * math.ceil((self.acceleration + self.deceleration) / self.jerk / tick
                                   / 2) + 1

    def _fixed_rates(self, cruise: float) -> np.ndarray:
        """In run-up distance d(v) the acceleration curve from any point grows by one
        metre per metre, so the forward pass is a running minimum too."""
        x = self.positions
        run_up = self.run_up(np.minimum(self.caps, cruise))
        run_up[0] = self.run_up(np.array(self.start_speed))
        squared = self.run_up_speed(np.minimum.accumulate(run_up - x) + x) ** 2
        fall = 2.0 * self.deceleration * (x[-1] - x)
        squared[-1] = 0.0
        squared = (np.minimum.accumulate((squared - fall)[::-1]) + fall[::-1])[::-1]
        if self.stop_jerk > 0.0:
            squared = np.minimum(squared, self.stopping(x[-1] - x) ** 2)
        return np.sqrt(np.maximum(squared, 0.0))

    def _feasible(self, train: TrainParameters, share: float, train_length: float
                  ) -> np.ndarray:
        """The curve without a cruise speed, each cell's rate the planned one or what the
        share of the envelope's force gives against the resistance, whichever is lower
        (forward then backward pass)."""
        x = self.positions
        line_resistance = self.line.additional_resistances(x, train_length)
        on = ~self.line.in_neutral_sections(x - train.pantograph_offset, self.neutral_runout)
        self.cells = Cells(on, line_resistance,
                           np.flatnonzero(~on & np.concatenate(([True], on[:-1]))), train, share)
        squared = self.caps ** 2
        squared[0] = self.start_speed ** 2
        forward_pass(squared, 0, x, on, line_resistance, train.envelope, train.davis_a,
                     train.davis_b, train.davis_c, train.xi, share, self.acceleration,
                     self.power_speed, self.start_speed ** 2, True)
        stopping = self.stopping(x[-1] - x) ** 2 if self.stop_jerk > 0.0 else squared
        backward_pass(squared, x, stopping, line_resistance, train.envelope, train.davis_a,
                      train.davis_b, train.davis_c, train.xi, share, self.deceleration)
        return np.sqrt(squared)

    def _rounded(self, speeds: np.ndarray) -> np.ndarray:
        """The curve with its acceleration changing at most at `jerk` (see the class
        docstring), in time along the curve itself, then back onto the grid: round_corners
        over T = max(a, b) / jerk (a, b the planned acceleration and deceleration), and
        around each turn from traction straight into braking the centred mean of that
        over W = (a + b) / jerk (an odd number of ticks).

        Why the second mean: round_corners alone turns a traction straight into braking
        with a jump of about (a + b) / 2 in acceleration where its two means cross (the
        lower of them switches), and its ramps there change a + b over T: 1.4 m/s^3 for a
        0.6 m/s^3 jerk. A centred mean over W of any curve whose acceleration stays within
        [-b, a] (round_corners' means of the curve do) changes its acceleration by at most
        (a + b) / W = jerk, whatever the curve does. Centred, it stays under a concave
        corner, so braking still starts no later than the turn. Only around the turns
        (curve_passes.turn_weights): elsewhere round_corners' ramps already keep the jerk, and a
        curve without such a turn keeps round_corners' bits."""
        return rounded_curve(self.positions, speeds, self.limits - self.margin / 2,
                             self._stop_curve, self.deceleration, *self._rounding)

    @functools.cached_property
    def _stop_curve(self) -> np.ndarray:
        """The speed the braking into the mark allows at every grid point, m/s."""
        distance = self.positions[-1] - self.positions
        if self.stop_jerk > 0.0:
            return self.stopping(distance)
        return np.sqrt(2.0 * self.deceleration * distance)

    def stopping(self, distance: np.ndarray) -> np.ndarray:
        """Speed at `distance` before the mark on a stop whose braking eases off at
        stop_jerk: in time before the stop, deceleration j t up to the service value
        b (v = j t^2 / 2, d = j t^3 / 6), constant b before that."""
        j, b = self.stop_jerk, self.deceleration
        ease = b / j                                   # s of easing off
        ease_distance, ease_speed = j * ease ** 3 / 6.0, j * ease ** 2 / 2.0
        easing = 0.5 * j * np.cbrt(6.0 * np.maximum(distance, 0.0) / j) ** 2
        braking = np.sqrt(ease_speed ** 2 + 2.0 * b * np.maximum(distance - ease_distance, 0.0))
        return np.where(distance <= ease_distance, easing, braking)

    def run_time(self, cruise: float) -> float:
        """The running time of the curve for a cruise speed, s (see the class docstring)."""
        return self.time_of(self.curve(cruise))

    def time_of(self, v: np.ndarray) -> float:
        """The running time of the speeds `v` on this curve's grid (one of its curves), s."""
        cells = float(running_time(self.positions, v))
        if self.departure is None:
            return cells
        x = self.positions
        eased = 0.5 * (2.0 * (x[-1] - x[-2]) / (v[-2] + v[-1])) if self.stop_jerk > 0.0 else 0.0
        return cells + self.departure + eased

    def passing_time(self, at: float) -> float:
        """When the curve passes `at` (m from its start), s after its departure (its time
        from standstill, as its running time counts)."""
        cells = np.concatenate(([0.0], np.cumsum(cell_times(self.positions, self.speeds))))
        return (self.departure or 0.0) + float(np.interp(at, self.positions, cells))

    def speed(self, t: float, position: float = 0.0) -> float:
        if position >= self.positions[-1]:
            return 0.0
        return float(np.interp(position, self.positions, self.speeds))

    def table(self) -> PlanTable:
        return self._table

    @functools.cached_property
    def _table(self) -> PlanTable:
        """Built once per curve (a curve is shared by every run of its parameters, and
        simulate() asks for it twice per run: 1-2 ms for a long line)."""
        return plan_table(self.positions, self.speeds, stops_at_end=True, limits=self.limits)

    def limit(self, position: float) -> float:
        """The limit that applies to the train with its head at `position`, m/s."""
        cell = np.searchsorted(self.positions, position, side="right") - 1
        return float(self.limits[min(max(cell, 0), len(self.limits) - 1)])


def _backward_pass(squared, x, stopping, line_resistance, envelope, davis_a, davis_b, davis_c,
                   xi, share, deceleration) -> None:
    """The backward pass of AtoCurve._feasible, in place on squared speeds: 0 at the last
    cell, each cell before it the lowest of its own value, `stopping` there and what the
    lower of the planned deceleration and the share of the brake envelope helped by the
    resistance (train.net_braking's terms) gives from the next. Compiled when numba is
    installed (it steps through every cell of the line)."""
    v2 = squared[len(x) - 1] = 0.0
    for i in range(len(x) - 2, -1, -1):
        v = math.sqrt(v2)
        braking = basic_resistance(v, davis_a, davis_b, davis_c) + line_resistance[i] \
            - share * force_limits(v, envelope)[0]
        rate = min(deceleration, xi * braking)
        v2 = min(v2 + 2.0 * max(rate, 0.0) * (x[i + 1] - x[i]), squared[i], stopping[i])
        squared[i] = v2


backward_pass = compiled(_backward_pass) or _backward_pass


LATE_NOTICE = 0.05  # s an on-time curve may miss the planned time by without a notice


def ato_curve(values: dict, line, train: TrainParameters, ceiling: Ceiling | None = None
              ) -> AtoCurve:
    """The ATO curve a run's profile.ato.* parameters give on `line` for `train` (the
    run context's: the train the ATO knows), kept under `ceiling` if given."""
    return _ato_curve(*ato_curve_arguments(values, line, train), ceiling)


def ato_curve_arguments(values: dict, line, train: TrainParameters) -> tuple:
    """What the ATO curve of `values` on `line` for `train` is built from (new_ato_curve's
    arguments, in order): the key of any cache of curves."""
    if values["profile.ato.neutral_runout"] > 0.0 and not values["profile.envelope_share"]:
        raise ScenarioError("profile.ato.neutral_runout needs profile.envelope_share > 0 (the "
                            "curve without a share does not plan neutral sections)")
    return (line, values["profile.ato.acceleration"], values["profile.ato.deceleration"],
            values["profile.ato.margin"], values["profile.ato.start_speed"],
            values["plant.length"], values["profile.ato.power_speed"] or math.inf,
            values["profile.ato.stop_jerk"], train if values["profile.envelope_share"] else None,
            values["profile.envelope_share"], values["profile.jerk"],
            departure_time(values, train) if values["profile.ato.on_time"] else None,
            values["profile.ato.neutral_runout"])


def departure_time(values: dict, train: TrainParameters) -> float:
    """What a departure takes before the ato curve's start_speed, s: the train's dead time,
    its actuator lag (a first-order lag delays a ramp by its time constant) and the rise
    from standstill to start_speed: the departure ramp's (profile.departure_jerk), else at
    profile.jerk (else at the planned acceleration)."""
    start, jerk = values["profile.ato.start_speed"], values["profile.jerk"]
    ramp = departure_ramp(values, train, start)
    if ramp.rise > 0.0:
        return ramp.delay + ramp.rise
    rise = (math.sqrt(2.0 * start / jerk) if jerk > 0.0
            else start / values["profile.ato.acceleration"])
    return train.dead_time + train.actuator_lag + rise


class DepartureRamp(NamedTuple):
    """How a position-indexed target leaves standstill (profile.departure_jerk): 0 for
    `delay` s after the departure (the nominal train's dead time and actuator lag: what a
    command takes to move it), then up to `speed` (the plan's start speed, m/s) over
    `rise` s as a smoothstep, whose jerk peaks at profile.departure_jerk and whose
    acceleration is zero where it meets the curve's own rounded start. rise 0: no ramp."""

    delay: float  # s
    rise: float   # s
    speed: float  # m/s


NO_RAMP = DepartureRamp(0.0, 0.0, 0.0)


def departure_ramp(values: dict, train: TrainParameters, start_speed: float) -> DepartureRamp:
    """The ramp to `start_speed` of a train that departs with `train`'s dead time and lag."""
    jerk = values["profile.departure_jerk"]
    if jerk <= 0.0 or start_speed <= 0.0:
        return NO_RAMP
    # a smoothstep v0 (3 u^2 - 2 u^3) over T has its largest jerk, 6 v0 / T^2, at u = 0 and 1
    return DepartureRamp(train.dead_time + train.actuator_lag,
                         math.sqrt(6.0 * start_speed / jerk), start_speed)


@jitable
def departing(ramp: DepartureRamp, since: float, target: float) -> float:
    """`target` (m/s) `since` s after the departure, held under the departure ramp."""
    if ramp.rise <= 0.0 or since >= ramp.delay + ramp.rise:
        return target
    share = (since - ramp.delay) / ramp.rise
    if share <= 0.0:
        return 0.0
    return min(target, ramp.speed * share * share * (3.0 - 2.0 * share))


def new_ato_curve(line, acceleration, deceleration, margin, start_speed, train_length,
                  power_speed, stop_jerk, train, envelope_share, jerk, departure,
                  neutral_runout, ceiling: Ceiling | None = None,
                  floor: float | None = None) -> AtoCurve:
    """The curve of ato_curve_arguments (and a ceiling; `floor`: the lowest cap, m/s, for a
    curve that starts from a running train at start_speed; None: start_speed), built anew."""
    return AtoCurve(line, acceleration, deceleration, margin, start_speed, train_length,
                    power_speed=power_speed, stop_jerk=stop_jerk, train=train,
                    envelope_share=envelope_share, jerk=jerk, departure=departure,
                    neutral_runout=neutral_runout, ceiling=ceiling, floor=floor)


# One curve per distinct line and parameters (the profile and the scorer both need it; the
# bisection costs tens of ms; an AtoCurve is never changed once built); a journey asks for
# two curves per section (on time, fastest): the metro line's twelve
_ato_curve = functools.lru_cache(maxsize=16)(new_ato_curve)


STEP_PARAMETERS = (
    param("profile.step.speed", 10.0 * KMH, "step height, m/s", PROFILE_NODES, 0.0, 300.0),
    param("profile.step.time", 0.0, "step instant, s", PROFILE_NODES, 0.0, 1e7),
)
TABLE_PARAMETERS = (
    param("profile.table.file", "", "CSV table (time|position,speed); relative to the scenario "
          "file, else to msg_config/", PROFILE_NODES),
)
ATO_PARAMETERS = (
    param("profile.ato.acceleration", 0.8, "ATO curve: planned acceleration, m/s^2",
          PROFILE_NODES, 0.01, 5.0),
    param("profile.ato.power_speed", 0.0, "ATO curve: above this speed the planned acceleration "
          "falls as 1/v (constant power), m/s (0 = constant acceleration)", PROFILE_NODES,
          0.0, 300.0),
    param("profile.ato.deceleration", 0.8, "ATO curve: planned service braking, m/s^2",
          PROFILE_NODES, 0.01, 5.0),
    param("profile.ato.stop_jerk", 0.0, "ATO curve: the braking into the stop mark eases off at "
          "this jerk, m/s^3 (0 = full service braking to the mark)", PROFILE_NODES, 0.0, 10.0),
    param("profile.ato.margin", 5.0 * KMH, "ATO curve: distance kept below the line limit, m/s",
          PROFILE_NODES, 0.0, 50.0),
    param("profile.ato.start_speed", 0.3, "ATO curve: target at the departure point (a position-"
          "indexed curve is 0 there and would never start the train), m/s", PROFILE_NODES,
          0.01, 10.0),
    param("profile.ato.on_time", False, "ATO curve: bisect the cruise speed on the running time "
          "from standstill to standstill (the train's dead time, actuator lag and rounded "
          "start before start_speed; the eased stop's last metres), as the line's planned "
          "time counts it, and say at start-up when even the fastest curve misses that time "
          "(false = the curve's own time, the papers' setting)", PROFILE_NODES),
    param("profile.ato.neutral_runout", 0.0, "ATO curve with profile.envelope_share: coast on "
          "until the pantograph is this far past a neutral section, m: traction commanded "
          "only once it has left (ladrc.neutral_cut) acts after the actuator's dead time and "
          "lag and the jerk limit's ramp, some (dead time + lag) x speed metres on (0 = "
          "traction planned from the section's end)", PROFILE_NODES, 0.0, 1000.0),
)


def _table(values, context) -> TableProfile:
    if not values["profile.table.file"]:
        raise ScenarioError("profile.kind is table but profile.table.file is empty")
    try:
        return TableProfile.from_csv(values["profile.table.file"])
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None


def _ato(values, context) -> AtoCurve:
    line = context.line
    if line is None:
        raise ScenarioError("profile.kind is ato but line.file is empty")
    if line.stop_position <= 0.0:
        raise ScenarioError(f"the ato profile needs a stop beyond the departure point; "
                            f"{values['line.file']} stops at 0 m")
    return ato_curve(values, line, context.plan_train)


STRATEGY_PARAMETERS = (
    param("profile.strategy.file", "", "strategy file (scripts/optimize_strategy.py) planned "
          "for this run's line and train; relative to the scenario file, else to msg_config/",
          PROFILE_NODES),
    param("profile.strategy.start_speed", 0.3, "strategy target at the departure point, m/s",
          PROFILE_NODES, 0.01, 10.0),
    param("profile.strategy.replan", False, "when the ATO's train is heavier than the nominal "
          "one (train.load_weighing), drive the strategy file's switching points again for it "
          "at the file's envelope share, moved towards flat out until it meets the file's "
          "planned time (flat out at profile.strategy.max_share at most); false: the file as "
          "planned", PROFILE_NODES),
    param("profile.strategy.max_share", 1.0, "with profile.strategy.replan: the highest share "
          "of the weighed train's envelopes a late plan may rise to (at the file's share or "
          "below: the file's reserve is kept, a heavy train arrives late)", PROFILE_NODES,
          0.1, 1.0),
)


def _strategy(values, context) -> StrategyProfile:
    from . import strategy  # the DP and its helpers are not needed by the other kinds
    path = values["profile.strategy.file"]
    if not path:
        raise ScenarioError("profile.kind is strategy but profile.strategy.file is empty")
    if context.line is None:
        raise ScenarioError("profile.kind is strategy but line.file is empty")
    try:
        plan = strategy.read_strategy(path)
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None
    line_digest = hashlib.sha256(Path(values["line.file"]).read_bytes()).hexdigest()
    if plan.header.get("line_sha256") != line_digest:
        raise ScenarioError(f"strategy file {path} was planned for another line "
                            f"({plan.header.get('line', '?')}), not {values['line.file']}")
    if plan.header.get("train") != values["plant.train"]:
        raise ScenarioError(f"strategy file {path} was planned for train "
                            f"{plan.header.get('train')!r}, the run uses "
                            f"{values['plant.train'] or '(none)'!r}")
    if abs(plan.positions[-1] - context.line.stop_position) > 1.0:
        raise ScenarioError(f"strategy file {path} ends at {plan.positions[-1]:.0f} m, the "
                            f"line's stop is at {context.line.stop_position:.0f} m")
    if values["profile.strategy.replan"] and context.plan_train != TrainParameters.from_values(
            values):  # the weighed train, heavier than the one planned for
        try:
            plan = _driven_again(StrategyByContents.of(plan), context.line, context.plan_train,
                                 values["plant.efficiency"],
                                 values["profile.strategy.max_share"])
        except ValueError as exc:
            raise ScenarioError(f"strategy file {path}: {exc}") from None
    return StrategyProfile(plan, values["profile.strategy.start_speed"])


@dataclass(frozen=True)
class StrategyByContents:
    """A strategy file as read, compared and hashed by the sha256 of its contents (a key of
    _driven_again's cache: a file rewritten in place is driven again)."""

    plan: Any = field(compare=False)  # strategy.StrategyFile
    digest: str

    @classmethod
    def of(cls, plan) -> StrategyByContents:
        digest = hashlib.sha256(repr(sorted(plan.header.items())).encode())
        for column in (plan.positions, plan.speeds, plan.modes, plan.forces):
            digest.update(column.tobytes())
        return cls(plan, digest.hexdigest())


@functools.lru_cache(maxsize=8)
def _driven_again(planned: StrategyByContents, line: Line, train: TrainParameters,
                  efficiency: float, max_share: float):
    """strategy.for_train, once per process for each strategy, line (a Line compares by
    its contents too) and weighed train (0.1-2.5 s: a tuning's candidates and a study's
    runs of one train share it; never changed by a caller)."""
    from . import strategy
    return strategy.for_train(planned.plan, line, train, efficiency, max_share)


SEED000 = Component(
    "seed000", "seed 000 eq. 25, time-indexed", SEED000_PARAMETERS,
    lambda values, context: Seed000Profile(**{
        spec.name.rsplit(".", 1)[1]: values[spec.name] for spec in SEED000_PARAMETERS}))
STEP = Component(
    "step", "a speed step at a given time", STEP_PARAMETERS,
    lambda values, context: StepProfile(values["profile.step.speed"], values["profile.step.time"]))
TABLE = Component("table", "CSV table against time or position", TABLE_PARAMETERS, _table)
STRATEGY = Component("strategy", "a driving strategy from scripts/optimize_strategy.py "
                     "(seed 002), distance-indexed", STRATEGY_PARAMETERS, _strategy)
ATO = Component("ato", "distance-indexed ATO curve from the line, braking and planned run time",
                ATO_PARAMETERS, _ato)
