"""The least-energy run of a section and of a journey, by a dynamic programme of its own
(ROS-free): the check of the project's planner (core/targets/strategy.py and journey.py),
whose code it does not use.

The train is the project's mass belt on a Line: basic resistance w0(v) (Davis), the
belt's gradient, curve and tunnel resistance (Line.additional_resistances with the train's
length), the traction envelope min(F_T, P_T / v), none while the pantograph is in a
neutral section, the brake envelope min(F_B, P_B / v), the speed limit over the whole belt
(lowered by `margin`, 0: up to the limit). The energy is the scorer's net energy
(core/scoring/operation.py): traction at the pantograph through the traction efficiency,
less what the braking regenerates, min(B, F_r, P_r / v) through the regeneration
efficiency (`Regeneration`; Regeneration(force=0.0): nothing regenerated, the traction
energy alone, which the project's programme minimises).

Grid: stage boundaries every `ds` metres (the stop mark the last), speeds every `dv` m/s.
From a speed v at a boundary the train may reach any grid speed w at the next one, over a
stage on which v^2 changes linearly with distance (the specific force is then whatever
that takes at every point, checked against both envelopes at the stage's start, middle and
end; its time 2 ds / (v + w) is exact, its energy Simpson's over the three points); and it
may coast, or drive at full traction or full brake, along the arc integrated exactly
(RK4 in d(v^2/2)/ds, SUBSTEPS steps a stage) to the speed that arc arrives at, off the
grid, where the next boundary's value is interpolated in speed: a coast is never rounded
onto the grid. The run itself is rolled out from standstill with the arrival speeds kept
exact: at every boundary the best of those moves from the speed the train really has.

Cost energy + lambda x time; the price lambda (kW) is bisected until the run meets its
running time; between the two runs that bracket it the energy is interpolated (the lower
convex hull of E(T), where E(T) jumps). A journey (sections with fixed dwells, the running
times' sum fixed) has one price for all its sections: at the optimum every section's
marginal energy dE/dT is the same.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.kernels import compiled, jitable
from ato_nodes.core.run.scoring import run_line
from ato_nodes.core.scoring.operation import KJ_PER_KWH, Regeneration, electric_force
from ato_nodes.core.targets.timetable import load_timetable, section_line
from ato_nodes.core.train.line import Line
from ato_nodes.core.train.plant import TrainParameters

SUBSTEPS = 4          # RK4 steps along an arc over one stage
LOWEST_PRICE = 1e-3   # kW per s: the bisection's bracket of lambda
HIGHEST_PRICE = 1e5
PRICE_RESOLUTION = math.log(1.0005)  # the bisection ends with lambda known this closely
HINT_RATIO = 1.5      # a hint's bracket: from the hinted price over this to it times this
FORCE_TOLERANCE = 1e-6  # N/kN: a linear move asking this much beyond an envelope is in it
BRAKING_STEPS = 48    # bisection steps of a braking top speed
TIME_TOLERANCE = 1e-3  # s: a run this close to its running time ends the bisection


class Stages(NamedTuple):
    """The line as the programme sees it: stage i from boundaries[i] to boundaries[i + 1]."""

    boundaries: np.ndarray  # (stages + 1,) m, 0 to the stop mark
    resistance: np.ndarray  # (stages, 2 SUBSTEPS + 1) N/kN at equally spaced points
    cap: np.ndarray         # (stages,) m/s: the lowest limit over the belt, less the margin
    powered: np.ndarray     # (stages,) bool: the pantograph outside every neutral section
    top: np.ndarray         # (stages + 1,) m/s: the highest speed at each boundary


class Drive(NamedTuple):
    """The train as the programme sees it: resistance per unit weight (N/kN), envelopes
    (kN, kW), efficiencies."""

    xi: float                 # m/s^2 per N/kN
    davis_a: float
    davis_b: float
    davis_c: float
    weight: float             # kN
    traction_force: float     # kN
    traction_power: float     # kW
    brake_force: float        # kN
    brake_power: float        # kW
    efficiency: float         # traction
    regenerative_force: float  # kN
    regenerative_power: float  # kW
    returned: float           # the regeneration efficiency


class Run(NamedTuple):
    """One run of a section: speeds at the stage boundaries and what each stage costs."""

    positions: np.ndarray  # m, the stage boundaries
    speeds: np.ndarray     # m/s at them
    traction_kwh: float    # at the pantograph
    regenerated_kwh: float
    time: float            # s, standstill to standstill
    price: float           # kW per s: the lambda it was made with

    @property
    def net_kwh(self) -> float:
        return self.traction_kwh - self.regenerated_kwh


def stages_of(line: Line, train: TrainParameters, ds: float, margin: float = 0.0) -> Stages:
    """The stages of `line` from 0 to its stop mark: at most `ds` m long, with a boundary
    wherever the limit over the belt changes (the head meets a limit's start or end, the
    tail leaves it), so that every stage's cap is its own, not its neighbour's."""
    stop = line.stop_position
    changes = {x + shift for limit in line.speed_limits for x in (limit.start, limit.end)
               for shift in (0.0, train.length)}
    changes = np.array(sorted(x for x in changes if 0.0 < x < stop))
    count = max(1, math.ceil(stop / ds - 1e-9))
    uniform = np.linspace(0.0, stop, count + 1)
    apart = np.array([not len(changes) or np.min(np.abs(changes - x)) > 0.25 * ds
                      for x in uniform])
    apart[[0, -1]] = True
    boundaries = np.unique(np.concatenate((uniform[apart], changes)))
    starts, ends = boundaries[:-1], boundaries[1:]
    points = starts[:, None] + (ends - starts)[:, None] * np.linspace(0.0, 1.0,
                                                                      2 * SUBSTEPS + 1)[None, :]
    resistance = line.additional_resistances(points.ravel(), train.length).reshape(points.shape)
    cap = np.array([_lowest_limit(line, max(0.0, a - train.length), b)
                    for a, b in zip(starts, ends, strict=True)]) - margin
    offset = train.pantograph_offset
    powered = np.array([not any(n.start < b - offset and n.end > a - offset
                                for n in line.neutral_sections)
                        for a, b in zip(starts, ends, strict=True)])
    top = np.minimum(np.append(cap, cap[-1]), np.append(cap[0], cap))
    return Stages(boundaries, resistance, cap, powered, top)


def _lowest_limit(line: Line, start: float, end: float) -> float:
    """The lowest speed limit anywhere on [start, end] (m), m/s."""
    return min(limit.value for limit in line.speed_limits
               if limit.start < end and limit.end > start)


def drive_of(train: TrainParameters, efficiency: float, regeneration: Regeneration) -> Drive:
    return Drive(train.xi, train.davis_a, train.davis_b, train.davis_c,
                 train.mass * train.gravity, train.max_traction_force,
                 train.max_traction_power, train.max_brake_force, train.max_brake_power,
                 efficiency, regeneration.force, regeneration.power,
                 regeneration.returned(efficiency))


@jitable
def _envelopes(v: float, drive: Drive) -> tuple[float, float]:
    """(brake, traction) at v, both >= 0, N/kN."""
    speed = max(v, 1e-6)
    traction = min(drive.traction_force, drive.traction_power / speed)
    brake = min(drive.brake_force, drive.brake_power / speed)
    return brake * 1000.0 / drive.weight, traction * 1000.0 / drive.weight


@jitable
def _w0(v: float, drive: Drive) -> float:
    return drive.davis_a + drive.davis_b * v + drive.davis_c * v * v


@jitable
def _per_metre(force: float, v: float, drive: Drive) -> tuple[float, float]:
    """(traction drawn, energy regenerated) per metre under the specific force `force`
    at v, kJ/m."""
    kilonewtons = force * drive.weight / 1000.0
    if kilonewtons >= 0.0:
        return kilonewtons / drive.efficiency, 0.0
    electric = electric_force(-kilonewtons, v, drive.regenerative_force,
                              drive.regenerative_power)
    return 0.0, electric * drive.returned


@jitable
def _linear(stages: Stages, drive: Drive, i: int, v: float, w: float):
    """(feasible, traction kJ, regenerated kJ, time s) of stage i from v to w with v^2
    linear in distance."""
    ds, middle, end = stages.boundaries[i + 1] - stages.boundaries[i], SUBSTEPS, 2 * SUBSTEPS
    if v + w <= 0.0 or max(v, w) > stages.cap[i] + 1e-9:
        return False, 0.0, 0.0, 0.0
    rise = (w * w - v * v) / (2.0 * ds) / drive.xi  # N/kN of the change of speed
    traction, regenerated = 0.0, 0.0
    for point, weight in ((0, 1.0), (middle, 4.0), (end, 1.0)):
        speed = math.sqrt(max(0.0, v * v + (w * w - v * v) * point / end))
        force = rise + _w0(speed, drive) + stages.resistance[i, point]
        brake, most = _envelopes(speed, drive)
        if not stages.powered[i]:
            most = 0.0
        if force > most + FORCE_TOLERANCE or force < -brake - FORCE_TOLERANCE:
            return False, 0.0, 0.0, 0.0
        drawn, returned = _per_metre(force, speed, drive)
        traction += weight * drawn * ds / 6.0
        regenerated += weight * returned * ds / 6.0
    return True, traction, regenerated, 2.0 * ds / (v + w)


@jitable
def _arc_force(kind: int, v: float, powered: bool, drive: Drive) -> float:
    """The specific force of an arc: 0 coast, 1 full traction, 2 full brake, N/kN."""
    brake, traction = _envelopes(v, drive)
    if kind == 1:
        return traction if powered else 0.0
    return -brake if kind == 2 else 0.0


@jitable
def _arc_rate(stages: Stages, drive: Drive, i: int, kind: int, energy: float, point: int
              ) -> float:
    """d(v^2/2)/ds along an arc at v^2/2 = `energy` (> 0) and the stage's `point`."""
    speed = math.sqrt(2.0 * energy)
    return drive.xi * (_arc_force(kind, speed, stages.powered[i], drive) - _w0(speed, drive)
                       - stages.resistance[i, point])


@jitable
def _arc(stages: Stages, drive: Drive, i: int, v: float, kind: int):
    """(feasible, arrival speed, traction kJ, regenerated kJ, time s) of stage i from v
    along an arc (`_arc_force`), integrated by RK4 in v^2/2; not feasible where it stops
    or passes the limit."""
    h = (stages.boundaries[i + 1] - stages.boundaries[i]) / SUBSTEPS
    if v <= 0.0 or (kind == 1 and not stages.powered[i]):
        return False, 0.0, 0.0, 0.0, 0.0
    energy, traction, regenerated, time = 0.5 * v * v, 0.0, 0.0, 0.0
    for q in range(SUBSTEPS):
        first = _arc_rate(stages, drive, i, kind, energy, 2 * q)
        trial = energy + 0.5 * h * first
        second = _arc_rate(stages, drive, i, kind, trial, 2 * q + 1) if trial > 0.0 else 0.0
        trial = energy + 0.5 * h * second
        third = _arc_rate(stages, drive, i, kind, trial, 2 * q + 1) if trial > 0.0 else 0.0
        trial = energy + h * third
        fourth = _arc_rate(stages, drive, i, kind, trial, 2 * q + 2) if trial > 0.0 else 0.0
        following = energy + h / 6.0 * (first + 2.0 * second + 2.0 * third + fourth)
        if min(trial, following) <= 0.0:
            return False, 0.0, 0.0, 0.0, 0.0
        a, b = math.sqrt(2.0 * energy), math.sqrt(2.0 * following)
        if b > stages.cap[i] + 1e-9:
            return False, 0.0, 0.0, 0.0, 0.0
        for speed in (a, b):
            drawn, returned = _per_metre(_arc_force(kind, speed, stages.powered[i], drive),
                                         speed, drive)
            traction += 0.5 * h * drawn
            regenerated += 0.5 * h * returned
        time += 2.0 * h / (a + b)
        energy = following
    return True, math.sqrt(2.0 * energy), traction, regenerated, time


@jitable
def _node(j: int, dv: float, top: float) -> float:
    """The speed of grid node j at a boundary whose highest speed is `top`: j dv, the last
    node top itself."""
    return min(j * dv, top)


@jitable
def _nodes(dv: float, top: float) -> int:
    """How many grid nodes a boundary with the highest speed `top` has."""
    return int(math.ceil(top / dv - 1e-9)) + 1


@jitable
def _value_at(values: np.ndarray, w: float, dv: float, top: float) -> float:
    """The next boundary's value at speed w: cubic through the four grid speeds around it
    (Catmull-Rom) where they are evenly spaced and all in reach, else linear between the
    two; inf above `top`."""
    if w > top + 1e-9:
        return math.inf
    last = _nodes(dv, top) - 1
    j = min(int(w / dv), last)
    if j == last:
        return values[j]
    low, high = values[j], values[j + 1]
    share = (w - j * dv) / (_node(j + 1, dv, top) - j * dv)
    if share <= 1e-12:
        return low
    linear = (1.0 - share) * low + share * high
    if j < 1 or j + 2 >= last or not (values[j - 1] < math.inf and values[j + 2] < math.inf
                                      and linear < math.inf):
        return linear
    before, after = values[j - 1], values[j + 2]
    return low + 0.5 * share * (high - before + share * (2.0 * before - 5.0 * low + 4.0 * high
                                                         - after + share * (3.0 * (low - high)
                                                                            + after - before)))


@jitable
def _best(stages: Stages, drive: Drive, i: int, v: float, following: np.ndarray,
          dv: float, price: float):
    """The best move over stage i from speed v given the next boundary's values:
    (cost, arrival speed, traction kJ, regenerated kJ, time s); cost inf: none."""
    best = (math.inf, 0.0, 0.0, 0.0, 0.0)
    top = stages.top[i + 1]
    nodes = _nodes(dv, top)
    first = int(math.ceil(v / dv - 1e-9))
    for direction in (1, -1):
        j = first if direction == 1 else min(first, nodes) - 1
        while 0 <= j < nodes:
            w = _node(j, dv, top)
            ok, traction, regenerated, time = _linear(stages, drive, i, v, w)
            if not ok and _beyond(stages, drive, i, v, w, direction):
                break
            if ok and following[j] < math.inf:
                cost = traction - regenerated + price * time + following[j]
                if cost < best[0]:
                    best = (cost, w, traction, regenerated, time)
            j += direction
    for kind in range(3):
        ok, w, traction, regenerated, time = _arc(stages, drive, i, v, kind)
        if ok:
            w = min(w, top) if w <= top + 1e-9 else w  # a braking top's arc lands on it
            cost = traction - regenerated + price * time + _value_at(following, w, dv, top)
            if cost < best[0]:
                best = (cost, w, traction, regenerated, time)
    return best


@jitable
def _beyond(stages: Stages, drive: Drive, i: int, v: float, w: float, direction: int) -> bool:
    """Whether going from v to w, and so to any speed further in `direction`, asks more at
    the stage's start than the envelope there gives (the force needed rises with w)."""
    ds = stages.boundaries[i + 1] - stages.boundaries[i]
    force = (w * w - v * v) / (2.0 * ds) / drive.xi + _w0(v, drive) \
        + stages.resistance[i, 0]
    brake, traction = _envelopes(v, drive)
    if direction == 1:
        return force > (traction if stages.powered[i] else 0.0) + 1e-9
    return force < -brake - 1e-9


def _backward(stages: Stages, drive: Drive, speeds: int, dv: float, price: float
              ) -> np.ndarray:
    """The value (kJ: energy + price x time to the stop) at every boundary and grid node
    (`_node`); inf where the stop cannot be reached."""
    count = len(stages.cap)
    values = np.full((count + 1, speeds), np.inf)
    values[count, 0] = 0.0
    for i in range(count - 1, -1, -1):
        top = stages.top[i]
        for j in range(min(speeds, _nodes(dv, top))):
            values[i, j] = _best(stages, drive, i, _node(j, dv, top), values[i + 1], dv,
                                 price)[0]
    return values


def _braking_tops(stages: Stages, drive: Drive) -> np.ndarray:
    """The highest speed at every boundary from which the train can still keep every limit
    ahead and stop at the mark: backwards from the stop, the speed whose full-brake arc over
    the stage arrives at the next boundary's (bisected; the last stage's at a standstill by
    the linear move), under the stage's cap. Each boundary's top speed is then a node of its
    own, so a full-brake arc lands on a node and is never rounded to a gentler brake."""
    count = len(stages.cap)
    tops = stages.top.copy()
    tops[count] = 0.0
    for i in range(count - 1, -1, -1):
        low, high = 0.0, tops[i]
        for _ in range(BRAKING_STEPS):
            middle = 0.5 * (low + high)
            if i == count - 1:
                arrives = _linear(stages, drive, i, middle, 0.0)[0]
            else:
                ok, w = _arc(stages, drive, i, middle, 2)[:2]
                arrives = not ok and middle <= stages.cap[i] or ok and w <= tops[i + 1] + 1e-12
            if arrives:
                low = middle
            else:
                high = middle
        tops[i] = low
    return tops


braking_tops = compiled(_braking_tops) or _braking_tops
backward = compiled(_backward) or _backward
best_move = compiled(_best) or _best


class Section(NamedTuple):
    """A section ready for the programme: its stages, the train and the speed grid."""

    stages: Stages
    drive: Drive
    dv: float

    @property
    def speeds(self) -> int:
        return int(math.ceil(float(np.max(self.stages.top)) / self.dv - 1e-9)) + 1


def section_of(line: Line, train: TrainParameters, efficiency: float,
               regeneration: Regeneration, ds: float, dv: float, margin: float = 0.0
               ) -> Section:
    stages = stages_of(line, train, ds, margin)
    drive = drive_of(train, efficiency, regeneration)
    return Section(stages._replace(top=braking_tops(stages, drive)), drive, dv)


def sections_between(line: Line, stops: list[float], train: TrainParameters,
                     efficiency: float, regeneration: Regeneration, ds: float, dv: float,
                     margin: float = 0.0) -> list[Section]:
    """section_of for each section of `line` between consecutive `stops` (m)."""
    return [section_of(section_line(line, start, end), train, efficiency, regeneration, ds,
                       dv, margin) for start, end in zip(stops, stops[1:], strict=False)]


def run_at(section: Section, price: float) -> Run:
    """The least-cost run at `price` (kW per s), rolled out from standstill with every
    arrival speed exact; ValueError if the stop cannot be reached."""
    stages, drive, dv = section
    values = backward(stages, drive, section.speeds, dv, price)
    if not math.isfinite(values[0, 0]):
        raise ValueError("the stop cannot be reached under the limits on this grid")
    speeds, traction, regenerated, time = [0.0], 0.0, 0.0, 0.0
    for i in range(len(stages.cap)):
        cost, w, drawn, returned, seconds = best_move(stages, drive, i, speeds[-1],
                                                      values[i + 1], dv, price)
        if not math.isfinite(cost):
            raise ValueError(f"the run finds no move at stage {i} ({speeds[-1]:.3f} m/s)")
        speeds.append(w)
        traction, regenerated, time = traction + drawn, regenerated + returned, time + seconds
    return Run(stages.boundaries, np.array(speeds), traction / KJ_PER_KWH, regenerated / KJ_PER_KWH,
               time, price)


class Optimum(NamedTuple):
    """The least energy in a running time: the runs either side of it (`early` meets it,
    `late` misses it; the same run when one meets it within TIME_TOLERANCE) and the
    energy interpolated between them."""

    running_time: float  # s
    net_kwh: float
    traction_kwh: float
    early: tuple[Run, ...]  # per section
    late: tuple[Run, ...]

    @property
    def price(self) -> float:
        return self.early[0].price


def journey_optimum(sections: list[Section], running_time: float,
                    around: float | None = None) -> Optimum:
    """The least net energy of the sections' runs with their times together
    `running_time` s (one price for all of them); a section alone is a journey of one.
    `around`: a price near the answer (a coarser grid's), where the bisection starts.
    ValueError if even the highest price's runs take longer."""
    def runs(price: float) -> tuple[Run, ...]:
        return tuple(run_at(section, price) for section in sections)

    early, late = _bracket(runs, running_time, around)
    if early is None:
        early = runs(HIGHEST_PRICE)
        if _total(early) > running_time + TIME_TOLERANCE:
            raise ValueError(f"the running time {running_time:g} s is shorter than the "
                             f"fastest runs ({_total(early):.1f} s)")
        late = runs(LOWEST_PRICE)
    low, high = math.log(late[0].price), math.log(early[0].price)
    while (_total(late) > running_time and high - low > PRICE_RESOLUTION
           and abs(_total(early) - running_time) > TIME_TOLERANCE):
        middle = 0.5 * (low + high)
        found = runs(math.exp(middle))
        if _total(found) > running_time:
            low, late = middle, found
        else:
            high, early = middle, found
    return _interpolated(running_time, early, late if _total(late) > running_time else early)


def _total(runs: tuple[Run, ...]) -> float:
    return sum(run.time for run in runs)


def _bracket(runs, running_time: float, around: float | None):
    """(early, late) runs at prices either side of `around` that bracket the running
    time, (None, None) when there is no such hint or it brackets nothing."""
    if around is None:
        return None, None
    early, late = runs(around * HINT_RATIO), runs(around / HINT_RATIO)
    if _total(early) <= running_time < _total(late):
        return early, late
    return None, None


def _interpolated(running_time: float, early: tuple[Run, ...], late: tuple[Run, ...]
                  ) -> Optimum:
    """The energy at `running_time` on the segment between the early and the late runs."""
    span = _total(late) - _total(early)
    share = 0.0 if span <= TIME_TOLERANCE else (running_time - _total(early)) / span

    def energy(kind: str) -> float:
        return ((1.0 - share) * sum(getattr(run, kind) for run in early)
                + share * sum(getattr(run, kind) for run in late))

    return Optimum(running_time, energy("net_kwh"), energy("traction_kwh"), early, late)


# A tuning's bound: stages of at least 10 m and a thousandth of the run, speeds every
# 0.1 m/s (scripts/energy_optimum.py's grid study puts 10 m x 0.1 m/s within 0.3 % of its
# finest grid on the metro line)
BOUND_STAGE, BOUND_STAGES, BOUND_SPEED_STEP = 10.0, 1000, 0.1


def least_energy_of_run(values: dict) -> tuple[float, float]:
    """(kWh, s): the least traction energy in which the scenario's nominal train can make
    its run in its planned running time -- a journey's stops in its timetable's running
    time, else its line's departure and stop in line.planned_run_time -- on the train's
    whole envelope, up to the limits, its departure at once: a bound no candidate of a
    tuning (any controller, any curve) can beat on that train. ScenarioError for a run
    without a stop or a planned time."""
    if values["profile.kind"] == "journey":
        timetable = load_timetable(values["profile.journey.timetable"])
        line, running_time = timetable.line, timetable.running_time
        stops = [stop.position for stop in timetable.stops]
    else:
        line = run_line(values)
        if line is None or line.stop_position <= 0.0 or line.planned_run_time is None:
            raise ScenarioError("the least energy needs a run to a stop in a planned time")
        stops = [0.0, line.stop_position]
        running_time = line.planned_run_time
    train = TrainParameters.from_values(values)
    stage = max(BOUND_STAGE, (stops[-1] - stops[0]) / BOUND_STAGES)
    sections = sections_between(line, stops, train, values["plant.efficiency"],
                                Regeneration(force=0.0), stage, BOUND_SPEED_STEP)
    return journey_optimum(sections, running_time).traction_kwh, running_time
