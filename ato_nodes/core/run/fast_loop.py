"""The lockstep loop compiled (numba), for the runs that tuning and studies repeat.

simulate() hands a run here when numba is installed and the run is of the kind a
compiled loop covers: any controller kind (compiled when its registry entry names its
ControllerSteps, core/control/stepped.py; else its own Python step called from the
compiled loop, core/run/python_steps.py), a time-indexed target (its horizons are
computed once per plan) or a position-indexed one with a PlanTable (the ATO curve,
a strategy, a position table: their horizons along the planned trajectory, step by
step), the point-mass train on the open track or on a line (gradients, curves,
tunnels, limits, neutral sections as LineTables arrays), dead time, lag, envelopes,
the noisy, quantised speed sensor and seed 003's stepped approach. Anything else
(live gain changes, a time-indexed target with the stepped approach or the plan's own
speed limits; none shipped) runs the Python loop. The step is the one core/run/stages.py
describes, in the same order, and every formula is the Python path's own jitable
function (core/base/kernels.py) reading the same NamedTuples by name;
tests/test_fast_loop.py checks that both paths give the same bits for every shipped
scenario the loop covers.

The controller kind is chosen by the type of its state: controller_start() and
controller_step() below resolve, while compiling, to the kind's own functions, so
one loop serves every kind, compiled once per kind (and once for all the kinds
without compiled steps; once more per kind for journeys, whose tables are an argument of
their own, None in other runs, so that their loops compile without a journey's code; once
more per kind with the on-board estimator on, whose settings and state are None in the
kind's when it is off, core/control/estimation.py) and cached on disk (numba keys its
cache by the argument types; loop.warm() compiles them all).

A run is computed in chunks of steps, each one call of the compiled loop lasting
about CHUNK_SECONDS, so that simulate() can check its deadline between them (a
step at 10000 RK4 sub-steps takes ~1 ms); everything a step changes goes from one
chunk to the next in a LoopState, by name, and the chunks give the bits of one
uninterrupted call.
"""

from __future__ import annotations

import math
import time
from contextlib import contextmanager
from typing import Any, Callable, NamedTuple

import numpy as np

from ..base.kernels import AVAILABLE, compiled, jitable, overload
from ..config.components import CONTROLLERS
from ..control.limiter import LimiterSettings
from ..scoring.indices import RunningIndex, running_add
from ..targets.horizons import ProfileSettings, ProfileState, plan_speed_limit, profile_step
from ..targets.served import JourneyTable
from ..train.line import line_arrays
from ..train.plant import (
    TrainMotion,
    TrainSettings,
    basic_resistance,
    disturbance,
    sensor_reading,
    train_acceleration,
    train_line_resistance,
    train_step,
)
from .last_stop import LastStop, held, standing
from .python_steps import PYTHON_STEPS, PythonController, running
from .stages import COLUMNS, SeriesColumns

# The compiled steps of every controller kind by the type of its state; the kinds
# without them share PYTHON_STEPS (their own Python step, called from compiled code).
STEPS_BY_STATE = {component.steps.state_type: component.steps
                  for component in CONTROLLERS.components.values() if component.steps}
STEPS_BY_STATE[PythonController] = PYTHON_STEPS


def compiled_kinds() -> list[str]:
    """One controller kind for each compiled step (loop.warm() compiles each; the
    kinds without compiled steps share one more)."""
    kinds = {component.steps.state_type: kind
             for kind, component in CONTROLLERS.components.items() if component.steps}
    return sorted(kinds.values())


def covers(profile, plant, controller, changes) -> bool:
    """Whether the compiled loop runs this run (stages built by simulate())."""
    plan = profile.context.plan
    if plan.position_indexed:  # a table, or a journey's tables
        drawable = plan.table() is not None or hasattr(plan, "journey")
    else:  # its horizons are computed once, without the stepped approach
        drawable = profile.approach_step <= 0.0 and not plan.limits_speed
    return AVAILABLE and not changes and drawable


class LoopInputs(NamedTuple):
    """What every step of a compiled run reads and none changes."""

    draws: np.ndarray          # the speed sensor's normal draws, one per step
    noise: float               # plant.speed_noise
    quantum: float             # plant.speed_quantum
    period: float              # s
    train: TrainSettings       # the real train's, on its line
    max_speed: float           # m/s, past it the run has diverged
    last_stop: LastStop        # where and how long a journey's train stands before the end
    profile: ProfileSettings   # the profile step's
    settings: Any              # the controller kind's settings NamedTuple
    limits: LimiterSettings
    fitness_kind: int          # the pruned running fitness: indices.ITAE, IAE, MAX_ABS_ERROR
    fitness_limit: float       # the running fitness past which the run ends (inf: never)
    columns: SeriesColumns     # where each series goes in a row


class FitnessState(NamedTuple):
    """A RunningIndex's value, last_t and last_w."""

    value: float
    last_t: float
    last_w: float


class LoopState(NamedTuple):
    """Everything a step changes, carried from one chunk of steps to the next: a run
    computed in chunks gives the bits of one computed in a single call."""

    step: int                  # the next step k
    plant: TrainMotion
    profile: ProfileState
    controller: Any            # the controller kind's state NamedTuple
    last: float                # the limiter's last command
    fitness: FitnessState
    stood: int                 # samples the train has stood at its last stop (PlantStage's)
    ended: bool                # diverged, pruned or arrived: no step follows


FIRST_CHUNK = 64  # steps computed by a run's first call of the compiled loop
CHUNK_SECONDS = 0.05  # wall time each later call aims at: the deadline is checked between calls


def run(profile, plant, controller, prune: tuple[RunningIndex, float] | None,
        check: Callable[[int], None]):
    """The run, compiled: (rows (steps x len(SERIES)), the controller's outputs
    (steps x outputs), the horizons). It runs in chunks of steps, each a call of the
    compiled loop lasting about CHUNK_SECONDS; `check(step)` is called before each
    (simulate() raises there once past its deadline)."""
    total = profile.context.steps
    # a journey's tables, else None: the loops of other runs compile without its code
    journey = profile.journey
    targets = profile.targets  # a time-indexed plan's given, else filled in as the run goes
    running_index, limit = prune if prune is not None else (RunningIndex("itae"), math.inf)
    rows = np.empty((total, len(COLUMNS)))
    extras = np.empty((total, len(controller.output_names)))
    with _controller_seam(controller) as (settings, controller_state):
        inputs = _inputs(profile, plant, controller, settings, running_index, limit)
        loop = _first_state(profile, plant, controller, controller_state, running_index)
        chunk = FIRST_CHUNK
        while loop.step < total and not loop.ended:
            check(loop.step)
            started = time.perf_counter()
            loop = _steps(inputs, journey, loop, min(total, loop.step + chunk), targets, rows,
                          extras)
            elapsed = time.perf_counter() - started
            chunk = max(1, min(4 * chunk, int(chunk * CHUNK_SECONDS / max(elapsed, 1e-9))))
    running_index.value, running_index.last_t, running_index.last_w = loop.fitness
    return rows[:loop.step], extras[:loop.step], targets[:loop.step]


@contextmanager
def _controller_seam(stage):
    """(settings, state) the compiled loop steps the stage's controller with: a kind's
    compiled steps read its own; any other kind is called in Python
    (core/run/python_steps.py)."""
    if stage.component.steps is not None:
        yield stage.controller.settings, stage.controller.state
        return
    with running(stage.controller) as slot:
        yield slot, slot


def _inputs(profile, plant, controller, settings, running_index, limit: float) -> LoopInputs:
    train = plant.train
    total = profile.context.steps
    # the sensor's draws, as PlantStage.measure takes them (one per step, the same stream)
    draws = plant.rng.standard_normal(total) if plant.noise > 0.0 else np.zeros(total)
    return LoopInputs(
        draws=draws, noise=float(plant.noise), quantum=float(plant.quantum),
        period=float(train.settings.period),
        train=train.settings._replace(line=line_arrays(train.line)),  # arrays: compiled code's
        max_speed=float(plant.max_speed), last_stop=plant.last_stop,
        profile=profile.settings._replace(line=line_arrays(train.line)),
        settings=settings, limits=controller.limiter.settings,
        fitness_kind=int(running_index.kind), fitness_limit=float(limit), columns=COLUMNS)


def _first_state(profile, plant, controller, controller_state, running_index) -> LoopState:
    return LoopState(
        step=0, plant=plant.train.motion,
        profile=profile.state,
        controller=controller_state, last=float(controller.limiter.last),
        fitness=FitnessState(float(running_index.value), float(running_index.last_t),
                             float(running_index.last_w)),
        stood=int(plant.stood), ended=False)


def controller_start(settings, state, target: float, measured: float):
    """The kind's ControllerSteps.start, chosen by the type of `state`."""
    return STEPS_BY_STATE[type(state)].start(settings, state, target, measured)


def controller_step(settings, state, target: float, measured: float, horizon, last: float,
                    limits: LimiterSettings):
    """The kind's ControllerSteps.step, chosen by the type of `state`."""
    return STEPS_BY_STATE[type(state)].step(settings, state, target, measured, horizon, last,
                                            limits)


if AVAILABLE:  # in compiled code the kind's function is chosen while compiling
    @overload(controller_start)
    def _compiled_start(settings, state, target, measured):
        start = STEPS_BY_STATE[state.instance_class].start
        return lambda settings, state, target, measured: start(settings, state, target,
                                                                measured)

    @overload(controller_step)
    def _compiled_step(settings, state, target, measured, horizon, last, limits):
        step = STEPS_BY_STATE[state.instance_class].step
        return lambda settings, state, target, measured, horizon, last, limits: step(
            settings, state, target, measured, horizon, last, limits)


def _steps_source(inputs: LoopInputs, journey: JourneyTable | None, loop: LoopState,
                  stop: int, targets, rows, extras) -> LoopState:
    """simulate()'s loop for the runs `covers` accepts, from step loop.step up to `stop`
    (or the step the run ends at); the state after. `targets` holds every step's
    horizon: given (time-indexed plans) or filled in LOOKAHEAD steps ahead."""
    k, plant, profile, controller, last, fitness, stood = (loop.step, loop.plant, loop.profile,
                                                           loop.controller, loop.last,
                                                           loop.fitness, loop.stood)
    ended = False
    while k < stop and not ended:
        measured = sensor_reading(plant.speed, inputs.draws[k], inputs.noise, inputs.quantum)
        profile = profile_step(inputs.profile, journey, profile, k, plant.position, targets)
        horizon = targets[k]
        reference = horizon[inputs.profile.preview]
        if k == 0:
            controller = controller_start(inputs.settings, controller, reference, measured)
        u, outputs, controller = controller_step(inputs.settings, controller, reference,
                                                 measured, horizon, last, inputs.limits)
        last = u
        _record(inputs, journey, rows[k], k, plant, horizon[0], measured, u)
        for i in range(len(outputs)):
            extras[k, i] = outputs[i]
        speed = plant.speed
        stood = standing(inputs.last_stop, stood, plant.position, speed)  # PlantStage.apply
        plant = train_step(inputs.train, plant, u)
        if not (abs(plant.speed) <= inputs.max_speed):  # PlantStage.diverged
            ended = True
        else:
            fitness = FitnessState(*running_add(
                inputs.fitness_kind, fitness.value, fitness.last_t, fitness.last_w,
                k * inputs.period, horizon[0] - speed))
            ended = fitness.value > inputs.fitness_limit or held(inputs.last_stop, stood)
        k += 1
    return LoopState(k, plant, profile, controller, last, fitness, stood, ended)


@jitable(inline=True)
def _record(inputs: LoopInputs, journey: JourneyTable | None, row, k: int, plant: TrainMotion,
            target: float, measured: float, command: float) -> None:
    """Step k's row of the SERIES (PlantStage.outputs at t_k, the target and command)."""
    train, column, x, v = inputs.train.constants, inputs.columns, plant.position, plant.speed
    line_resistance = train_line_resistance(inputs.train, plant)
    row[column.t], row[column.target], row[column.position] = k * inputs.period, target, x
    row[column.measured_speed], row[column.speed] = measured, v
    row[column.acceleration] = train_acceleration(inputs.train, plant, line_resistance)
    row[column.disturbance] = disturbance(plant.time, train.disturbance_amplitude,
                                          train.disturbance_frequency, train.disturbance_phase)
    row[column.force] = plant.force
    row[column.resistance] = basic_resistance(v, train.davis_a, train.davis_b, train.davis_c)
    row[column.line_resistance] = line_resistance
    row[column.speed_limit] = plan_speed_limit(inputs.profile, journey, x)
    row[column.command] = command


_steps = compiled(_steps_source)
