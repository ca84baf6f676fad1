"""The lockstep loop compiled (numba), for the runs that tuning repeats most.

simulate() hands a run here when numba is installed and the run is of the kind a
compiled loop covers: Han's ADRC (seed 000 and seed 003's NLADRC), a time-indexed
target without the stepped approach, the point-mass train on the open track
(no line) with no dead time; lag, envelopes and the noisy, quantised speed sensor
included. Everything else (lines, position-indexed curves, other controllers,
dead time, live gain changes) runs the Python loop. The step is the one
core/run/stages.py describes, in the same order, and every formula is the Python path's
own function (core/base/kernels.py's jitable: plant.rates, rk4_substep and
sensor_reading, adrc.han_adrc_step, limiter.limit_command, indices.running_add),
compiled, reading the same NamedTuples by name;
tests/test_fast_loop.py checks that both paths give the same bits.

A run is computed in chunks of steps, each one call of the compiled loop lasting
about CHUNK_SECONDS, so that simulate() can check its deadline between them (a
step at 10000 RK4 sub-steps takes ~1 ms); everything a step changes goes from one
chunk to the next in a LoopState, by name, and the chunks give the bits of one
uninterrupted call. Every covered run calls the loop with the same argument types,
so it is compiled once (loop.warm(): scripts/setup.sh, a tuning before its workers
start) and loaded from numba's cache by every later process.

The targets of a time-indexed plan do not depend on the run, so the horizons are
computed once per process and plan, by the ProfileStage itself, and reused by
every tuning candidate.
"""

from __future__ import annotations

import functools
import json
import math
import time
from typing import Callable, NamedTuple

import numpy as np

from ..base.kernels import AVAILABLE, compiled
from ..config.schema import NodeValues
from ..control.adrc import HanADRCGains, HanADRCState, han_adrc_start, han_adrc_step
from ..control.limiter import LimiterSettings
from ..scoring.indices import RunningIndex, running_add
from ..train.line import LineTables, belt_resistance, line_tables
from ..train.plant import (
    TrainConstants,
    achievable,
    basic_resistance,
    disturbance,
    rates,
    rk4_substep,
    sensor_reading,
)
from .stages import COLUMNS, ProfileStage, SeriesColumns


def covers(profile, plant, controller, changes) -> bool:
    """Whether the compiled loop runs this run (stages built by simulate()): a controller
    kind whose registry entry names a step this module has a loop for, and a run of the
    kind that loop covers."""
    train, plan = plant.train, profile.context.plan
    return (AVAILABLE and not changes and controller.component.compiled_step in LOOPS
            and not plan.position_indexed and not plan.limits_speed
            and profile.approach_step <= 0.0
            and profile.context.line is None and train.line is None and not train.delayed)


@functools.lru_cache(maxsize=4)
def _horizons(profile_values: str) -> np.ndarray:
    profile = ProfileStage(NodeValues("profile", json.loads(profile_values)))
    rows = []
    while len(rows) < profile.total_steps:
        rows.extend(profile.on_position(0.0))  # time-indexed: the position is not read
    return np.array(rows, dtype=float)


def horizons(profile) -> np.ndarray:
    """Every step's horizon (steps x (N + 1)) as a ProfileStage publishes them, computed
    once per process and plan (read-only: shared by every run of the plan)."""
    table = _horizons(json.dumps(dict(profile.context.values), sort_keys=True))
    table.flags.writeable = False
    return table


class LoopInputs(NamedTuple):
    """What every step of a compiled run reads and none changes."""

    targets: np.ndarray        # every step's horizon (steps x (N + 1)), read-only
    draws: np.ndarray          # the speed sensor's normal draws, one per step
    noise: float               # plant.speed_noise
    quantum: float             # plant.speed_quantum
    preview: int               # the horizon entry the controller tracks
    period: float              # s
    substeps: int              # RK4 sub-steps per period
    powered: bool              # traction power (always, on the open track)
    train: TrainConstants
    lagged: bool               # the force follows the command through the actuator lag
    max_speed: float           # m/s, past it the run has diverged
    gains: HanADRCGains
    limits: LimiterSettings
    fitness_kind: int          # the pruned running fitness: indices.ITAE, IAE, MAX_ABS_ERROR
    fitness_limit: float       # the running fitness past which the run ends (inf: never)
    columns: SeriesColumns     # where each series goes in a row
    line: LineTables           # arrays (empty: the open track)


class LoopState(NamedTuple):
    """Everything a step changes, carried from one chunk of steps to the next: a run
    computed in chunks gives the bits of one computed in a single call."""

    step: int                  # the next step k
    plant_steps: int           # periods the train has run (PointMassTrain.steps)
    time: float                # s, the plant's clock
    position: float            # m
    speed: float               # m/s, true
    force: float               # N/kN applied
    lag: float                 # the lag's output before the envelope (PointMassTrain.lag_state)
    acting: float              # the command that acted over the last period
    controller: HanADRCState
    last: float                # the limiter's last command
    fitness: float             # the running fitness (RunningIndex value, last_t, last_w)
    fitness_last_t: float
    fitness_last_w: float
    ended: bool                # diverged or pruned: no step follows


FIRST_CHUNK = 64  # steps computed by a run's first call of the compiled loop
CHUNK_SECONDS = 0.05  # wall time each later call aims at: the deadline is checked between calls


def run(profile, plant, controller, prune: tuple[RunningIndex, float] | None,
        check: Callable[[int], None]):
    """The run, compiled: (rows (steps x len(SERIES)), the controller's outputs
    (steps x 5), the horizons). It runs in chunks of steps, each a call of the
    compiled loop lasting about CHUNK_SECONDS; `check(step)` is called before each
    (simulate() raises there once past its deadline)."""
    targets = horizons(profile)
    train, han, limiter = plant.train, controller.controller, controller.limiter
    running, limit = prune if prune is not None else (RunningIndex("itae"), math.inf)
    rows = np.empty((len(targets), len(COLUMNS)))
    extras = np.empty((len(targets), 5))
    # the sensor's draws, as PlantStage.measure takes them (one per step, the same stream)
    draws = plant.rng.standard_normal(len(targets)) if plant.noise > 0.0 else \
        np.zeros(len(targets))
    inputs = LoopInputs(
        targets, draws, float(plant.noise), float(plant.quantum), int(controller.preview),
        float(train.period), int(train.substeps), bool(train.powered), train.constants,
        bool(train.lagged), float(plant.max_speed), han.gains, limiter.settings,
        int(running.kind), float(limit), COLUMNS, line_tables(None, np.array))
    state = train.state
    loop = LoopState(
        0, int(train.steps), float(state.time), float(state.position), float(state.speed),
        float(state.force), float(train.lag_state), float(train.acting), han.state,
        float(limiter.last), float(running.value), float(running.last_t),
        float(running.last_w), False)
    chunk = FIRST_CHUNK
    loop_of_kind = LOOPS[controller.component.compiled_step]
    while loop.step < len(targets) and not loop.ended:
        check(loop.step)
        started = time.perf_counter()
        loop = loop_of_kind(inputs, loop, min(len(targets), loop.step + chunk), rows, extras)
        elapsed = time.perf_counter() - started
        chunk = max(1, min(4 * chunk, int(chunk * CHUNK_SECONDS / max(elapsed, 1e-9))))
    running.value, running.last_t, running.last_w = \
        loop.fitness, loop.fitness_last_t, loop.fitness_last_w
    return rows[:loop.step], extras[:loop.step], targets[:loop.step]


def _han_adrc_steps_source(inputs: LoopInputs, loop: LoopState, stop: int, rows, extras
                           ) -> LoopState:
    """simulate()'s loop for the runs `covers` accepts with Han's ADRC, from step
    loop.step up to `stop` (or the step the run ends at); the state after."""
    train, targets, period, substeps = inputs.train, inputs.targets, inputs.period, \
        inputs.substeps
    column = inputs.columns
    sub = period / substeps
    plant_steps, clock, x, v, force = loop.plant_steps, loop.time, loop.position, loop.speed, \
        loop.force
    lag, acting, last, controller = loop.lag, loop.acting, loop.last, loop.controller
    fitness, fitness_last_t, fitness_last_w = \
        loop.fitness, loop.fitness_last_t, loop.fitness_last_w
    k, ended = loop.step, False
    while k < stop and not ended:
        # plant outputs at t_k (PlantStage.outputs)
        measured = sensor_reading(v, inputs.draws[k], inputs.noise, inputs.quantum)
        acceleration = rates(clock, v, lag, acting, inputs.powered,
                             belt_resistance(inputs.line, x, train.length), train)[0]
        reference = targets[k, inputs.preview]
        if k == 0:
            controller = han_adrc_start(controller, reference, measured)
        u, controller = han_adrc_step(controller, reference, measured, inputs.gains, period,
                                      last, inputs.limits)
        last = u
        row = rows[k]
        row[column.t], row[column.target], row[column.position] = k * period, targets[k, 0], x
        row[column.measured_speed], row[column.speed] = measured, v
        row[column.acceleration] = acceleration
        row[column.disturbance] = disturbance(clock, train.disturbance_amplitude,
                                              train.disturbance_frequency,
                                              train.disturbance_phase)
        row[column.force] = force
        row[column.resistance] = basic_resistance(v, train.davis_a, train.davis_b,
                                                  train.davis_c)
        row[column.line_resistance], row[column.speed_limit], row[column.command] = \
            0.0, math.inf, u
        extras[k, 0], extras[k, 1], extras[k, 2] = controller.z1, controller.z2, controller.z3
        extras[k, 3], extras[k, 4] = controller.v1, controller.v2
        speed = v
        # plant.apply(u) (PointMassTrain.step)
        start = clock
        for i in range(substeps):
            x, v, lag = rk4_substep(start + i * sub, x, v, lag, sub, u, inputs.powered,
                                    train, inputs.line)
        acting = u
        plant_steps += 1
        clock = plant_steps * period
        force = achievable(lag if inputs.lagged else u, v, train.limited, train.envelope)
        if not (abs(v) <= inputs.max_speed):  # PlantStage.diverged
            ended = True
        else:
            fitness, fitness_last_t, fitness_last_w = running_add(
                inputs.fitness_kind, fitness, fitness_last_t, fitness_last_w, k * period,
                targets[k, 0] - speed)
            ended = fitness > inputs.fitness_limit
        k += 1
    return LoopState(k, plant_steps, clock, x, v, force, lag, acting, controller, last,
                     fitness, fitness_last_t, fitness_last_w, ended)


# The compiled loops, by the controller step (a registry entry's compiled_step) each runs.
LOOPS = {han_adrc_step: compiled(_han_adrc_steps_source)} if AVAILABLE else {}
