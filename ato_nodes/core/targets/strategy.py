"""Driving strategies along a line (seed 002), ROS-free: the energy-optimal limit by
dynamic programming over (position, speed).

The train is the project's mass belt (core.plant.TrainParameters, core.line.Line):
basic resistance w0(v), the belt's gradient, curve and tunnel resistance, the
traction and brake envelopes, traction cut while the pantograph is in a neutral
section, speeds capped at the line limit over the belt minus a margin (seed 002's
speed protection: limit - 7 km/h). In distance, over a stage of length ds with a
specific force F (N/kN) held:

    d(v^2/2)/ds = xi (F - w0(v) - w_line(s))          (xi = g/1000/(1 + gamma))

integrated by Heun's method over the stage. Energy drawn: max(F, 0) m g / 1000 ds / eta
(kJ); time: ds / mean speed.

Dynamic programming (`solve`), backwards over stages of `ds` metres, on a grid of
speeds; at every node, each control of CONTROLS (full, 3/4, 1/2 and 1/4 traction,
cruise: F = the resistance, coasting, 1/4, 1/2 and full braking) leads to a next
speed, at which the next stage's value is interpolated (no snapping of transitions
to the grid, so coasting stays coasting); a control "land" (not in CONTROLS) takes the
train exactly onto the stage's cap or the highest grid speed from which the rest of the
run is feasible, whichever is lower (a top-up to a limit, a stop on the braking curve),
where the envelope allows it. The cost is energy + lambda * time;
lambda, the price of a second, is bisected (on a log scale) until the run meets the
planned time. The terminal state is standstill at the stop mark. `solve(..., lam=None,
energy_weight=0)` is the minimum-time (flat-out) run.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..base import yamlfile
from ..base.kernels import compiled, jitable
from ..base.units import KMH
from ..optimizers import optimize
from ..train.line import MAX_LENGTH, Line, in_neutral_section, speed_limit
from ..train.plant import Envelope, TrainParameters

MARGIN = 7.0 * KMH  # seed 002's speed protection: below the limit by this
# (kind, fraction): traction and braking as fractions of the envelope at the speed
CONTROLS = (("traction", 1.0), ("traction", 0.75), ("traction", 0.5), ("traction", 0.25),
            ("cruise", 0.0), ("coast", 0.0), ("brake", 0.25), ("brake", 0.5),
            ("brake", 1.0))
MODE = {"traction": 1, "cruise": 0, "coast": 0, "brake": -1}
LAND = "land"  # the kind of the control that lands on a target speed (mode by its sign)


@dataclass(frozen=True)
class Track:
    """The line as the DP sees it, one entry per stage [s_i, s_i + ds]."""

    positions: np.ndarray   # stage starts, m
    ds: float
    line_resistance: np.ndarray  # N/kN, the belt's, at the stage's middle
    cap: np.ndarray         # m/s, the highest allowed speed over the stage
    powered: np.ndarray     # bool: traction available over the whole stage

    @classmethod
    def of(cls, line: Line, train: TrainParameters, ds: float = 100.0,
           margin: float = MARGIN) -> Track:
        stages = max(1, round(line.stop_position / ds))
        ds = line.stop_position / stages
        starts = np.arange(stages) * ds
        tables = line.tables if track_columns is _track_columns else line.arrays
        cap, powered = track_columns(tables, starts, ds, train.length,
                                     train.pantograph_offset, line.length, margin)
        return cls(starts, ds, line.additional_resistances(starts + ds / 2, train.length),
                   cap, powered)


    @property
    def stop(self) -> float:
        """The stop mark: the end of the last stage, m."""
        return float(self.positions[-1] + self.ds)

    @property
    def boundaries(self) -> np.ndarray:
        """Stage starts and the stop mark, m."""
        return np.append(self.positions, self.stop)

    def without_neutral_sections(self) -> Track:
        """The same track powered everywhere (a plan that ignores neutral sections)."""
        return dataclasses.replace(self, powered=np.ones_like(self.powered))


@dataclass
class Strategy:
    """A driving strategy: per stage the control chosen and the speeds it gives."""

    positions: np.ndarray   # m, stage boundaries (stages + 1)
    speeds: np.ndarray      # m/s at the boundaries
    forces: np.ndarray      # N/kN applied over each stage
    modes: np.ndarray       # 1 traction, 0 cruise/coast, -1 brake, per stage
    controls: list[tuple[str, float]]
    energy_kwh: float
    time: float             # s
    lam: float              # kW: the price of a second that met the planned time
    switching: np.ndarray | None = None  # a switching strategy's decision variables

    def traction_in(self, sections) -> float:
        """Largest traction force in any stage that overlaps one of `sections`."""
        worst = 0.0
        for start, force in zip(self.positions[:-1], self.forces, strict=False):
            end = start + (self.positions[1] - self.positions[0])
            if force > 0 and any(start < sec.end and end > sec.start for sec in sections):
                worst = max(worst, force)
        return worst


class Problem:
    """The train on the track: stage transitions for every control at every speed. The
    plan uses `share` of the traction and brake envelopes (1: all of them; below 1 the
    rest is a reserve for a heavier or more resisted train than the one planned for)."""

    def __init__(self, track: Track, train: TrainParameters, efficiency: float,
                 share: float = 1.0, controls: tuple[tuple[str, float], ...] = CONTROLS):
        if not 0.0 < share <= 1.0:
            raise ValueError(f"the envelope share {share:g} is outside (0, 1]")
        self.track, self.train, self.efficiency = track, train, efficiency
        self.share, self.controls = share, controls
        kinds = [kind for kind, _ in controls]
        self.cruise = kinds.index("cruise")
        self.land = kinds.index(LAND) if LAND in kinds else None
        self.xi = train.xi
        self.physics = Physics(track.ds, track.line_resistance, track.cap, track.powered,
                               train.xi, train.davis_a, train.davis_b, train.davis_c,
                               train.envelope, share, efficiency)

    def forces(self, stage: int, v: np.ndarray, target: float = math.nan) -> np.ndarray:
        """(controls x speeds) specific force of every control at speeds v, N/kN; NaN
        where the control is not available (traction in a neutral section, a landing on
        `target` m/s beyond the envelope)."""
        brake, traction = self.limits(v)
        resistance = self.resistance(v) + self.track.line_resistance[stage]
        rows = []
        for kind, fraction in self.controls:
            if kind == "traction":
                row = fraction * traction
            elif kind == "brake":
                row = fraction * brake
            elif kind == "cruise":  # hold the speed if the envelope allows it
                row = np.where((resistance <= traction) & (resistance >= brake), resistance,
                               np.nan)
            elif kind == LAND:
                row = _force_for(self.physics, stage, v, target)
                row = np.where((row <= traction) & (row >= brake) & (v + target > 0.0), row,
                               np.nan)
            else:
                row = np.zeros_like(v)
            if not self.track.powered[stage]:
                row = np.where(row > 0, np.nan, row)
            rows.append(row)
        return np.array(rows)

    def limits(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _limits(v, self.physics)

    def resistance(self, v: np.ndarray) -> np.ndarray:
        return _resistance(v, self.physics)

    def energy(self, force):
        """Energy drawn over one stage under `force` (N/kN), kJ."""
        return _energy(force, self.physics)

    def step(self, stage: int, v: np.ndarray, force: np.ndarray) -> np.ndarray:
        """Speed at the end of the stage from v under force (see `_step`)."""
        return _step(self.physics, stage, v, force)


class Physics(NamedTuple):
    """A Problem as compiled code reads it (one tuple: compiled code pays for every array
    it hands to a function)."""

    ds: float                    # m, the stage length
    line_resistance: np.ndarray  # N/kN per stage
    cap: np.ndarray              # m/s per stage
    powered: np.ndarray          # bool per stage
    xi: float
    davis_a: float
    davis_b: float
    davis_c: float
    envelope: Envelope
    share: float                 # of the envelopes the plan uses
    efficiency: float


# The formulas below take a speed or an array of speeds (the dynamic programme's grid);
# numpy's maximum and minimum, so that both are one source.
@jitable
def _limits(v, physics: Physics):
    """(brake, traction): the share of the envelopes at v as specific forces, N/kN."""
    envelope = physics.envelope
    speed = np.maximum(np.abs(v), 1e-6)
    traction = np.minimum(envelope.max_traction_force, envelope.max_traction_power / speed)
    brake = np.minimum(envelope.max_brake_force, envelope.max_brake_power / speed)
    if physics.share != 1.0:
        traction, brake = physics.share * traction, physics.share * brake
    return -brake * 1000.0 / envelope.weight, traction * 1000.0 / envelope.weight


@jitable
def _resistance(v, physics: Physics):
    """The basic resistance w0 at v (>= 0), N/kN."""
    return physics.davis_a + physics.davis_b * v + physics.davis_c * v * v


@jitable
def _energy(force, physics: Physics):
    """Energy drawn over one stage under `force` (N/kN), kJ."""
    return (np.maximum(force, 0.0) * physics.envelope.weight / 1000.0 * physics.ds
            / physics.efficiency)


@jitable
def _step(physics: Physics, stage: int, v, force):
    """Speed at the end of the stage from v under force (Heun on v^2/2; the resistance at
    the predicted end speed too). 0 where the train stops short."""
    ds, extra = physics.ds, physics.line_resistance[stage]
    start = 0.5 * v * v
    first = physics.xi * (force - _resistance(v, physics) - extra)
    predicted = np.sqrt(np.maximum(0.0, 2.0 * (start + ds * first)))
    second = physics.xi * (force - _resistance(predicted, physics) - extra)
    return np.sqrt(np.maximum(0.0, 2.0 * (start + ds * 0.5 * (first + second))))


def _track_columns(tables, starts, ds, train_length, pantograph_offset, line_length, margin):
    """(cap, powered) of the stages from `starts` (Track.of): the lowest line limit at the
    belt's tail, the stage's start, middle and end, minus `margin`; whether the pantograph
    is outside every neutral section at the stage's start, middle and end."""
    cap = np.empty(len(starts))
    powered = np.empty(len(starts), dtype=np.bool_)
    for i in range(len(starts)):
        s = starts[i]
        lowest = math.inf
        for x in (s - train_length, s, s + ds / 2, s + ds):
            lowest = min(lowest, speed_limit(tables, min(max(0.0, x), line_length)))
        cap[i] = lowest - margin
        powered[i] = True
        for x in (s, s + ds / 2, s + ds):
            if in_neutral_section(tables, x - pantograph_offset):
                powered[i] = False
    return cap, powered


track_columns = compiled(_track_columns) or _track_columns


def _stage_costs(problem: Problem, stage: int, grid: np.ndarray, target: float = math.nan):
    forces = problem.forces(stage, grid, target)
    with np.errstate(invalid="ignore"):
        following = problem.step(stage, grid[None, :], np.nan_to_num(forces))
    cruise = problem.cruise
    following[cruise] = np.where(np.isnan(forces[cruise]), 0.0, grid)  # exactly held
    if problem.land is not None:  # exactly landed
        following[problem.land] = np.where(np.isnan(forces[problem.land]), 0.0, target)
    mean = 0.5 * (grid[None, :] + following)
    with np.errstate(divide="ignore"):
        seconds = np.where(mean > 1e-6, problem.track.ds / mean, np.inf)
    energy = problem.energy(np.nan_to_num(forces))
    feasible = ~np.isnan(forces) & (following <= problem.track.cap[stage] + 1e-9)
    return forces, following, seconds, energy, feasible


def solve(track: Track, train: TrainParameters, efficiency: float, planned_time: float | None,
          *, speed_step: float = 0.25, energy_weight: float = 1.0,
          lam: float | None = None, iterations: int = 40,
          controls: tuple[tuple[str, float], ...] = CONTROLS) -> Strategy:
    """The energy-optimal strategy that arrives in `planned_time` (lambda bisected), or
    for a given price of a second `lam`; energy_weight 0 (and any lam > 0) is the
    minimum-time run; `controls` the choices at every node (seed 002's CONTROLS). Raises
    ValueError if the planned time cannot be met."""
    problem = Problem(track, train, efficiency, controls=controls)
    grid = np.arange(0.0, float(track.cap.max()) + speed_step, speed_step)
    if lam is not None or planned_time is None:
        return _forward(problem, grid, energy_weight, 1.0 if lam is None else lam)
    fastest = _forward(problem, grid, 0.0, 1.0)
    if fastest.time > planned_time:
        raise ValueError(f"the planned time {planned_time:.0f} s is shorter than the "
                         f"flat-out run's {fastest.time:.1f} s")
    low, high = math.log(1e-3), math.log(1e6)  # kW per s of time saved
    best = None
    for _ in range(iterations):
        middle = 0.5 * (low + high)
        candidate = _forward(problem, grid, energy_weight, math.exp(middle))
        if candidate.time > planned_time:
            low = middle
        else:
            high, best = middle, candidate
        if best is not None and planned_time - best.time < 0.05:
            break
    return best if best is not None else _forward(problem, grid, energy_weight, math.exp(high))


INFEASIBLE = 1e30  # the value of a node from which the stop cannot be reached


def _choices(problem: Problem, stage: int, speeds: np.ndarray, following_value: np.ndarray,
             grid: np.ndarray, energy_weight: float, lam: float):
    """Total cost of every control from every speed (controls x speeds), and what the
    controls do: forces, end speeds, times, energies."""
    forces, following, seconds, energy, feasible = _stage_costs(
        problem, stage, speeds, _landing(problem, stage, following_value, grid))
    if stage < len(problem.track.positions) - 1:  # a train stopped short is stuck
        feasible &= following > 1e-9
    future = np.interp(following, grid, following_value)
    total = np.where(feasible & (future < INFEASIBLE / 2),
                     energy_weight * energy + lam * seconds + future, INFEASIBLE)
    return total, forces, following, seconds, energy


def _landing(problem: Problem, stage: int, following_value: np.ndarray, grid: np.ndarray
             ) -> float:
    """Where the control LAND takes the train over the stage, m/s: the stage's cap or the
    highest grid speed of the next boundary with a feasible value, the lower (NaN: no
    such control)."""
    if problem.land is None:
        return math.nan
    reachable = np.flatnonzero(following_value < INFEASIBLE / 2)
    top = float(grid[reachable[-1]]) if len(reachable) else 0.0
    return min(float(problem.track.cap[stage]), top)


def _values(problem: Problem, grid: np.ndarray, energy_weight: float, lam: float) -> list:
    """The value function on the grid at every stage boundary (the last: the mark)."""
    value = np.where(grid <= 1e-9, 0.0, INFEASIBLE)  # standing at the stop mark
    values = [value]
    for stage in range(len(problem.track.positions) - 1, -1, -1):
        value = _choices(problem, stage, grid, value, grid, energy_weight, lam)[0].min(axis=0)
        values.append(value)
    values.reverse()
    return values


def _forward(problem: Problem, grid: np.ndarray, energy_weight: float, lam: float) -> Strategy:
    """The value functions, then the run from standstill, each control chosen at the
    actual speed (no rounding of the speed to the grid)."""
    track = problem.track
    values = _values(problem, grid, energy_weight, lam)
    speeds, forces_taken, modes, controls = [0.0], [], [], []
    energy_total = time_total = 0.0
    for stage in range(len(track.positions)):
        total, forces, following, seconds, energy = _choices(
            problem, stage, np.array([speeds[-1]]), values[stage + 1], grid, energy_weight,
            lam)
        pick = int(np.argmin(total[:, 0]))
        if total[pick, 0] >= INFEASIBLE / 2:
            raise ValueError(f"no feasible way on from {track.positions[stage]:.0f} m at "
                             f"{speeds[-1]:.2f} m/s")
        speeds.append(float(following[pick, 0]))
        forces_taken.append(float(forces[pick, 0]))
        controls.append(problem.controls[pick])
        kind = problem.controls[pick][0]
        modes.append(int(np.sign(forces[pick, 0])) if kind == LAND else MODE[kind])
        energy_total += float(energy[pick, 0])
        time_total += float(seconds[pick, 0])
    return Strategy(track.boundaries, np.array(speeds), np.array(forces_taken),
                    np.array(modes), controls, energy_total / 3600.0, time_total, lam)


# Switching-point strategies (seed 002's decision variables) -----------------------
TAU = 60.0  # s: the time-error index exp(|T' - T| / TAU) is e at one minute off the plan
# G's weights (the paper leaves them to the user): energy and comfort relative to the
# flat-out run's, so each term is ~1 for a plain strategy; the stop error per 10 m; the
# speed protection weighs most (a strategy above limit - 7 km/h is not one to drive).
WEIGHTS = {"energy": 1.0, "time": 1.0, "comfort": 0.2, "stop": 1.0, "protection": 10.0}


def braking_curve(problem: Problem, service: float = 1.0) -> np.ndarray:
    """Highest speed at each stage boundary from which braking at `service` x the brake
    envelope keeps under every cap ahead and stops at the mark (backwards in distance)."""
    return braking_speeds(problem.physics, service)


def _braking_speeds(physics: Physics, service: float) -> np.ndarray:
    """braking_curve over the problem's tuple (compiled when numba is installed)."""
    stages = len(physics.cap)
    curve = np.zeros(stages + 1)
    for stage in range(stages - 1, -1, -1):
        after = min(curve[stage + 1], physics.cap[stage])
        # the weakest deceleration over the stage: the brake envelope at its start speed
        # (it falls with speed), the resistance at its end speed (it rises), so the
        # train can follow the curve
        start = after
        for _ in range(3):
            brake = _limits(start, physics)[0]
            deceleration = physics.xi * (-service * brake + _resistance(after, physics)
                                         + physics.line_resistance[stage])
            start = math.sqrt(after * after + 2.0 * physics.ds * max(deceleration, 1e-6))
        curve[stage] = min(physics.cap[stage], start)
    return curve


braking_speeds = compiled(_braking_speeds) or _braking_speeds


def segments(track: Track) -> list[tuple[int, int]]:
    """Stage ranges between neutral sections: [start, end) in stage indices, each ending
    where the next unpowered run begins (the last at the mark)."""
    bounds, previous = [0], True
    for stage, powered in enumerate(track.powered):
        if previous and not powered:
            bounds.append(stage)
        previous = powered
    bounds.append(len(track.powered))
    return [(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]


# Switching strategies brake along a curve at this share of the brake envelope: the
# margin a tracking controller with dead time and lag needs to follow it (measured:
# at the full envelope the stack's PID overran the stop by 23 m).
PLANNED_BRAKING = 0.8


class SwitchingStrategy:
    """Seed 002's decision variables, per segment between neutral sections: the cruise
    speed (a fraction of the segment's highest cap) and the point where coasting
    starts (a fraction of the segment). In a segment the train applies full traction
    up to the cruise speed, cruises (held at the cap where it is lower), coasts from
    the coasting point, and brakes along the braking curve (PLANNED_BRAKING of the
    envelope, or the problem's share if lower) wherever a lower cap ahead or the stop
    requires it. Traction is off while unpowered."""

    def __init__(self, problem: Problem):
        self.problem = problem
        self.segments = segments(problem.track)
        self.curve = braking_curve(problem, min(PLANNED_BRAKING / problem.share, 1.0))
        self.dimension = 2 * len(self.segments)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lower = np.tile([0.3, 0.0], len(self.segments))
        return lower, np.ones(self.dimension)

    def run(self, x: np.ndarray) -> Strategy:
        cruise, coasting = self.controls(x)
        result = _drive(self.problem, self.curve, cruise, coasting, NO_PLAN)
        result.switching = np.array(x, dtype=float)
        return result

    def controls(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per stage: the cruise speed (m/s) and whether it is past the coasting point."""
        cap = self.problem.track.cap
        cruise, coasting = np.empty(len(cap)), np.zeros(len(cap), dtype=bool)
        for k, (first, last) in enumerate(self.segments):
            cruise[first:last] = x[2 * k] * float(cap[first:last].max())
            coasting[first:last] = np.arange(first, last) >= first + x[2 * k + 1] * (last - first)
        return cruise, coasting


# The kinds of control a run's stage takes (the codes compiled code returns)
KINDS = ("traction", "cruise", "coast", "brake")
TRACTION, CRUISING, COASTING, BRAKING = range(len(KINDS))
KIND_MODES = np.array([MODE[kind] for kind in KINDS])
NO_PLAN = np.zeros(0)  # _drive's planned forces when the switching strategy decides
# The exponent of the brake correction's squares, handed to compiled code at run time: in
# Python x ** 2 is libm's pow, which compiled code turns into x * x when it knows the
# exponent (the two differ in the last bit for about one x in a thousand).
SQUARE = 2.0


def _drive(problem: Problem, curve: np.ndarray, cruise: np.ndarray, coasting: np.ndarray,
           planned: np.ndarray, lam: float = math.nan) -> Strategy:
    """A run from standstill, stage by stage (`driven`): the switching strategy's controls,
    or the `planned` forces replayed. A train that stops short of the mark ends where
    that stage begins, standing, with an infinite running time."""
    track = problem.track
    speeds, forces, kinds, energy, elapsed, stages = driven(
        problem.physics, curve, cruise, coasting, planned, SQUARE)
    positions = track.boundaries
    if stages < len(track.positions):  # stopped short: coasting to a stand at the stage
        positions = np.append(track.positions[:stages + 1], track.positions[stages])
        speeds, forces = np.append(speeds[:stages + 1], 0.0), np.append(forces[:stages], 0.0)
        kinds = kinds[:stages + 1]
    chosen = list(zip(map(KINDS.__getitem__, kinds.tolist()), forces.tolist(), strict=True))
    return Strategy(positions, speeds, forces, KIND_MODES[kinds], chosen,
                    float(energy) / 3600.0, float(elapsed), lam)


def _driven(physics: Physics, curve, cruise, coasting, planned, square):
    """(speeds at the boundaries, forces and kinds per stage, energy kJ, time s, stages
    driven) of a run from standstill: each stage's control chosen at the actual speed by
    the switching strategy (`_switched`), or the `planned` forces (if any) replayed. A train
    that stops short ends after the stages driven, coasting to a stand in the next, with
    an infinite time. Compiled when numba is installed."""
    stages = len(physics.cap)
    speeds, forces = np.zeros(stages + 1), np.zeros(stages)
    kinds = np.full(stages, COASTING)
    energy = elapsed = 0.0
    for stage in range(stages):
        v = speeds[stage]
        if len(planned):
            if stage >= len(planned):
                raise ValueError("the replayed plan stops short of where its run goes on")
            kind, force, following = _replayed(physics, stage, v, planned[stage])
        else:
            kind, force, following = _switched(physics, curve, stage, v, cruise[stage],
                                               coasting[stage], square)
        if following <= 1e-9 and stage < stages - 1:
            return speeds, forces, kinds, energy, math.inf, stage
        elapsed += physics.ds / max(0.5 * (v + following), 1e-6)
        energy += _energy(force, physics)
        speeds[stage + 1], forces[stage], kinds[stage] = following, force, kind
    return speeds, forces, kinds, energy, elapsed, stages


@jitable
def _switched(physics: Physics, curve, stage: int, v: float, cruise: float, coasting: bool,
              square: float):
    """(kind, force N/kN, end speed) of SwitchingStrategy's control at speed v."""
    brake, traction = _limits(v, physics)
    hold = _resistance(v, physics) + physics.line_resistance[stage]
    limit = min(curve[stage + 1], physics.cap[stage])
    if coasting:
        kind, force = COASTING, 0.0
    elif v < min(cruise, limit):
        kind, force = TRACTION, traction
    else:
        kind, force = CRUISING, min(max(hold, brake), traction)
    if not physics.powered[stage] and force > 0:
        kind, force = COASTING, 0.0
    following = _step(physics, stage, v, force)
    if kind == CRUISING and brake <= hold <= traction:
        following = v
    if following > limit:  # the braking curve or a cap: brake down to it
        kind = BRAKING
        force = max(brake, _force_for(physics, stage, v, limit))
        following = _step(physics, stage, v, force)
        if following > limit:  # correct by what the stage really gave
            force = max(brake, force - (following ** square - limit ** square)
                        / (2.0 * physics.ds * physics.xi))
            following = _step(physics, stage, v, force)
    return kind, force, following


@jitable
def _replayed(physics: Physics, stage: int, v: float, force: float):
    """(kind, force N/kN, end speed) of a planned force, traction cut where unpowered."""
    if not physics.powered[stage] and force > 0:
        force = 0.0
    kind = TRACTION if force > 0 else BRAKING if force < 0 else COASTING
    return kind, force, _step(physics, stage, v, force)


@jitable
def _force_for(physics: Physics, stage: int, v: float, target: float) -> float:
    """The specific force that takes speed v to `target` over the stage (Euler)."""
    resistance = _resistance(0.5 * (v + target), physics)
    return ((target * target - v * v) / (2.0 * physics.ds) / physics.xi + resistance
            + physics.line_resistance[stage])


driven = compiled(_driven) or _driven


def indices(result: Strategy, planned_time: float, track: Track) -> dict:
    """Seed 002's indices of a strategy on `track`: energy (kWh), time error
    exp(|T' - T| / TAU), comfort (sum of |change of acceleration| over the run time,
    m/s^3), stopping error |S - s| (m), speed protection (sum of the excess over the
    cap, m/s)."""
    v, cap, stop = result.speeds, track.cap, track.stop
    ds = np.maximum(np.diff(result.positions), 1e-9)
    acceleration = (v[1:] ** 2 - v[:-1] ** 2) / (2.0 * ds)
    finished = math.isfinite(result.time)
    return {
        "energy_kwh": result.energy_kwh,
        "time": result.time,
        "time_index": math.exp(min(abs(result.time - planned_time) / TAU, 50.0))
        if finished else math.exp(50.0),
        "comfort": float(np.abs(np.diff(acceleration)).sum() / result.time) if finished
        else math.inf,
        "stopping_error": abs(stop - result.positions[-1]) + overrun(result),
        "protection": float(np.maximum(0.0, v[1:len(cap) + 1] - cap[:len(v) - 1]).sum()),
    }


def flat_out(problem: Problem) -> Strategy:
    """The minimum-time run of a switching strategy: full traction up to the cap, held
    at the cap, braking along the braking curve (no coasting but through neutral
    sections)."""
    switching = SwitchingStrategy(problem)
    return switching.run(np.ones(switching.dimension))


def overrun(result: Strategy, deceleration: float = 0.5) -> float:
    """How far past the mark a strategy still moving at its end would stop, m (at a
    service deceleration, m/s^2): 0 for one that stands at the mark."""
    return float(result.speeds[-1]) ** 2 / (2.0 * deceleration)


def objective(values: dict, reference: dict) -> float:
    """G: the weighted sum of the indices, energy and comfort relative to `reference`
    (the flat-out run's), the stopping error per 10 m."""
    return (WEIGHTS["energy"] * values["energy_kwh"] / reference["energy_kwh"]
            + WEIGHTS["time"] * values["time_index"]
            + WEIGHTS["comfort"] * values["comfort"] / max(reference["comfort"], 1e-9)
            + WEIGHTS["stop"] * values["stopping_error"] / 10.0
            + WEIGHTS["protection"] * values["protection"])


# The strategy file ------------------------------------------------------------------
FORMAT = "ato-strategy-1"
# What a strategy file may hold: a 2,000 km line (line.MAX_LENGTH) in optimize_strategy.py's
# shortest stages (10 m) is 200,001 rows of at most ~35 bytes; speeds and forces beyond any
# train's (1,080 km/h, 1 g of specific force) are a broken or hostile file, not a plan.
MAX_FILE_BYTES = 8 << 20
MAX_SPEED = 300.0   # m/s
MAX_FORCE = 1000.0  # N/kN
COLUMNS = "position,speed,mode,force"


def write_strategy(path, header: dict, result: Strategy) -> None:
    """The strategy file: `# key: value` header lines (format, line and its sha256,
    train, planned time, algorithm, ...), then `position,speed,mode,force` rows (m, m/s,
    1 traction / 0 cruise or coast / -1 brake, N/kN) at every stage start and the end."""
    lines = [f"# {key}: {value}" for key, value in {"format": FORMAT, **header}.items()]
    lines.append(COLUMNS)
    forces = np.append(result.forces, 0.0)
    modes = np.append(result.modes, 0)
    lines += [f"{s:.1f},{v:.5f},{int(m)},{f:.5f}"
              for s, v, m, f in zip(result.positions, result.speeds, modes, forces, strict=False)]
    Path(path).write_text("\n".join(lines) + "\n")


@dataclass(frozen=True)
class StrategyFile:
    header: dict
    positions: np.ndarray
    speeds: np.ndarray
    modes: np.ndarray
    forces: np.ndarray


def read_strategy(path) -> StrategyFile:
    """A strategy file, checked (its size before it is read, then every row): ValueError
    (one line, naming the file and the line) if it is not one."""
    text = yamlfile.read_text(path, "strategy file", MAX_FILE_BYTES)
    header, rows = {}, []
    for number, line in enumerate(text.splitlines(), 1):
        if line.startswith("#"):
            key, _, value = line[1:].partition(":")
            header[key.strip()] = value.strip()
            continue
        if not line.strip():
            continue
        if header.get("format") != FORMAT:  # the header comes first
            raise _not_a_strategy(path, header)
        if line.strip() == COLUMNS:
            continue
        try:
            row = [float(v) for v in line.split(",")]
        except ValueError:
            row = []
        problem = _row_problem(row, rows[-1][0] if rows else None)
        if problem:
            raise ValueError(f"{path} line {number}: {problem}")
        rows.append(row)
    if header.get("format") != FORMAT:  # comments only
        raise _not_a_strategy(path, header)
    if len(rows) < 2:
        raise ValueError(f"{path}: a strategy needs at least two rows ({COLUMNS})")
    data = np.array(rows, dtype=float)
    return StrategyFile(header, data[:, 0], data[:, 1], data[:, 2].astype(int), data[:, 3])


def _not_a_strategy(path, header: dict) -> ValueError:
    return ValueError(f"{path}: not a strategy file (format {header.get('format')!r})")


def _row_problem(row: list[float], previous_position: float | None) -> str:
    """What is wrong with one row of a strategy file ('' if nothing)."""
    if len(row) != 4:
        return f"four numbers expected ({COLUMNS})"
    position, speed, mode, force = row
    if not all(math.isfinite(value) for value in row):
        return "every number must be finite"
    if not 0.0 <= position <= MAX_LENGTH:
        return f"position {position:g} m is off any line (0-{MAX_LENGTH:g} m)"
    if previous_position is not None and position <= previous_position:
        return f"position {position:g} m does not increase (after {previous_position:g} m)"
    if not 0.0 <= speed <= MAX_SPEED:
        return f"speed {speed:g} m/s is outside 0-{MAX_SPEED:g} m/s"
    if mode not in (-1.0, 0.0, 1.0):
        return f"mode {mode:g} is not 1 (traction), 0 (cruise or coast) or -1 (brake)"
    if abs(force) > MAX_FORCE:
        return f"force {force:g} N/kN is beyond +-{MAX_FORCE:g} N/kN"
    return ""


# Planning by algorithm ----------------------------------------------------------------
ALGORITHMS = ("kh", "pso", "dp", "mareco", "flatout")
MARECO_COAST = 0.85  # the coasting point of every segment, as a fraction of it


def plan(algorithm: str, problem: Problem, planning: Problem, planned: float,
         reference: dict, *, evaluations: int = 1500, seed: int = 1):
    """(strategy, optimizer result or None) of one algorithm. `planning` is the problem
    the plan is made on (without neutral sections, for the paper's comparison), `problem`
    the line as it is; G's reference is the flat-out run's indices."""
    if algorithm == "flatout":
        return flat_out(problem), None
    if algorithm == "dp":
        return solve(planning.track, planning.train, planning.efficiency, planned), None
    if algorithm == "mareco":
        return mareco(planning, planned), None
    switching = SwitchingStrategy(planning)

    def fitness(candidates):
        return np.array([objective(indices(switching.run(x), planned, problem.track),
                                   reference) for x in candidates])

    found = optimize(algorithm, fitness, *switching.bounds(), budget=evaluations, seed=seed)
    return switching.run(found.best_x), found


def mareco(problem, planned: float) -> Strategy:
    """One cruise speed for every segment, bisected until the run meets the planned
    time, coasting from MARECO_COAST of each segment on."""
    switching = SwitchingStrategy(problem)
    low, high = 0.3, 1.0
    best = switching.run(np.tile([high, MARECO_COAST], len(switching.segments)))
    for _ in range(30):
        middle = 0.5 * (low + high)
        candidate = switching.run(np.tile([middle, MARECO_COAST], len(switching.segments)))
        if candidate.time > planned:
            low = middle
        else:
            high, best = middle, candidate
    return best


def replay(problem: Problem, planned_result: Strategy) -> Strategy:
    """A plan made without neutral sections, driven on the line: each stage's force,
    traction cut where unpowered (ValueError where the plan, stopped short, has no force)."""
    stages = len(problem.track.positions)
    return _drive(problem, NO_PLAN, NO_PLAN, np.zeros(stages, dtype=bool),
                  np.asarray(planned_result.forces, dtype=float), planned_result.lam)


def problems(line: Line, values: dict, ds: float, ignore_neutral: bool = False,
             share: float = 1.0):
    """(the line as it is, the line the plan is made on) for the train of the run values
    `values` (plant.*) at `share` of its envelopes: the same problem unless the plan
    ignores neutral sections."""
    train = TrainParameters.from_values(values)
    track = Track.of(line, train, ds)
    problem = Problem(track, train, values["plant.efficiency"], share)
    if not ignore_neutral:
        return problem, problem
    return problem, Problem(track.without_neutral_sections(), train, values["plant.efficiency"],
                            share)


@dataclass
class Outcome:
    result: Strategy    # driven on the line as it is
    history: object     # the swarm's optimizers.Result, None for the other algorithms
    values: dict        # indices, G, planned, time_error, saved_percent, seconds, ...
    reference: dict     # the flat-out run's indices


def evaluate(algorithm: str, problem: Problem, planning: Problem, planned: float | None, *,
             supplement: float = 0.0, evaluations: int = 1500, seed: int = 1) -> Outcome:
    """One algorithm's strategy for the planned time (None: the flat-out run's time plus
    `supplement`, a share), judged on the line as it is (a plan made without neutral
    sections is driven with traction cut in them). ValueError if the planned time is
    shorter than the flat-out run's."""
    fastest = flat_out(problem)
    if planned is None:
        planned = fastest.time * (1.0 + supplement)
    if not planned >= fastest.time:
        raise ValueError(f"the planned time {planned:g} s is shorter than the flat-out "
                         f"run's {fastest.time:.1f} s")
    reference = indices(fastest, planned, problem.track)
    started = time.monotonic()
    result, history = plan(algorithm, problem, planning, planned, reference,
                           evaluations=evaluations, seed=seed)
    seconds = time.monotonic() - started
    if planning is not problem:
        result = replay(problem, result)
    values = indices(result, planned, problem.track)
    values.update(G=objective(values, reference), planned=planned,
                  time_error=result.time - planned, seconds=seconds,
                  saved_percent=100 * (1 - result.energy_kwh / fastest.energy_kwh),
                  flat_out_energy_kwh=fastest.energy_kwh)
    return Outcome(result, history, values, reference)


# The strategy for the train the ATO knows ---------------------------------------------
RECOVERY_STEPS = 12  # bisection steps along the recovery path (2^-11 of it)


def switching_points(plan: StrategyFile) -> np.ndarray:
    """The decision variables of a switching strategy's file (its `switching` header, as
    optimize_strategy.py writes it): ValueError (one line) if it has none."""
    text = plan.header.get("switching", "")
    try:
        x = np.array([float(value) for value in text.split(",")])
    except ValueError:
        x = np.zeros(0)
    if not len(x) or not np.all((x >= 0.0) & (x <= 1.0)):
        raise ValueError(f"the strategy of {plan.header.get('algorithm', '?')} has no "
                         f"switching points in [0, 1] (header 'switching': {text!r})")
    return x


def running_time(plan: StrategyFile) -> float:
    """The running time of a strategy file's rows: each stage at its mean speed, s."""
    speeds = np.maximum(0.5 * (plan.speeds[1:] + plan.speeds[:-1]), 1e-6)
    return float(np.sum(np.diff(plan.positions) / speeds))


def for_train(plan: StrategyFile, line: Line, train: TrainParameters,
              efficiency: float, max_share: float = 1.0) -> StrategyFile:
    """A switching strategy's file driven again for `train` (the weighed one): its
    switching points on the same stages, with that train's envelopes at the file's share
    (its braking curve too), so it stops on the mark. Where that misses the file's planned
    time (or its own running time, if later), the plan recovers along one path, bisected
    until the run meets the time: from recovery 0 to 1 every cruise speed and coasting
    point moves that fraction of its way to flat out (1, 1); from 1 to 2 the flat-out
    run's share rises from the file's to `max_share` (if higher). A train that cannot meet
    the time even so drives flat out at that share and arrives late."""
    x = switching_points(plan)
    ds = float(plan.positions[1] - plan.positions[0])
    track, share = Track.of(line, train, ds), float(plan.header.get("share", 1.0))
    planned = max(float(plan.header["planned_time_s"]), running_time(plan))
    switchings = {}

    def run(recovery: float) -> Strategy:
        level = share + max(recovery - 1.0, 0.0) * max(max_share - share, 0.0)
        if level not in switchings:
            switchings[level] = SwitchingStrategy(Problem(track, train, efficiency, level))
        switching = switchings[level]
        if len(x) != switching.dimension:
            raise ValueError(f"{len(x)} switching points, the line has {switching.dimension}")
        return switching.run(x + min(recovery, 1.0) * (1.0 - x))

    best = run(0.0)
    if best.time > planned:
        low, high, best = 0.0, 2.0, run(2.0)
        for _ in range(RECOVERY_STEPS if best.time <= planned else 0):
            middle = 0.5 * (low + high)
            candidate = run(middle)
            if candidate.time > planned:
                low = middle
            else:
                high, best = middle, candidate
    return StrategyFile({**plan.header, "time_for_train_s": f"{best.time:.3f}"},
                        best.positions, best.speeds, np.append(best.modes, 0),
                        np.append(best.forces, 0.0))
