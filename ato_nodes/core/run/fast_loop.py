"""The lockstep loop, written once: compiled (numba) when numba is installed, else, or
when simulate(compiled=False) asks, the same function run as Python (numba's py_func).

Step k runs the order core/run/stages.py describes, each stage by its own step
function over its settings and state NamedTuples: the train's (core/train/plant.py
train_step), the profile's (core/targets/horizons.py profile_step), the controller
kind's (core/control/stepped.py ControllerSteps; a kind without them calls its own
Python step, core/run/python_steps.py), the running fitness's (core/scoring/indices.py
running_step) and the last stop's (core/run/last_stop.py). The nodes' stages hold the
same states and call the same functions one step at a time, so the stack, the
compiled loop and the Python loop give the same bits (tests/test_stages.py).

Any run takes it: any controller kind, time-indexed targets (their horizons computed
once per plan), position-indexed ones with a PlanTable (the ATO curve, a strategy, a
position table: their horizons along the planned trajectory, step by step) or a
journey's tables, the point-mass train on the open track or on a line, dead time, lag,
envelopes, the noisy, quantised speed sensor, the stepped approach and live gain
changes: a step-indexed schedule of the controller's settings, the loop's chunks ending
at each change (ControllerStage.retune builds the new settings and carries the state).
A plan it cannot read is refused when its run context is built (RunContext.
profile_settings), in every runner alike.

The controller kind is chosen by the type of its state: controller_start() and
controller_step() below resolve, while compiling, to the kind's own functions, looked up
in the registry then (so a kind registered after import joins), so one loop serves every
kind, compiled once per kind (and once for all the kinds without compiled steps; once
more per kind for journeys, whose tables are an argument of their own, None in other
runs, so that their loops compile without a journey's code; once more per kind with the
on-board estimator on, whose settings and state are None in the kind's when it is off,
core/control/estimation.py) and cached on disk, each signature keyed by its argument
types and the sources it is built from: the loop's modules and its kind's, not the other
kinds' (_loop_sources, core/base/kernels.py); loop.warm() compiles them all.

A run is computed in chunks of steps, each one call of the loop lasting about
CHUNK_SECONDS, so that simulate() can check its deadline between them (a step at 10000
RK4 sub-steps takes ~1 ms compiled); everything a step changes goes from one chunk to
the next in a LoopState, by name, and the chunks give the bits of one uninterrupted call.
"""

from __future__ import annotations

import math
import time
from contextlib import contextmanager
from typing import Any, Callable, NamedTuple

import numpy as np

from ..base.kernels import AVAILABLE, Sources, compiled, jitable, overload
from ..config.components import CONTROLLERS
from ..control.limiter import LimiterSettings, held_at_rail
from ..control.stepped import ControllerSteps
from ..scoring.indices import RunningIndex, RunningState, running_step
from ..targets.horizons import ProfileSettings, ProfileState, plan_speed_limit, profile_step
from ..targets.served import JourneyTable
from ..train.line import line_arrays
from ..train.plant import TrainMotion, TrainSettings, diverged, drive_effort, sensor_reading, \
    train_outputs, train_step
from .last_stop import LastStop, held, standing
from .located import ODOMETRY_SERIES, adhesion_seen, located, odometer_moved
from .python_steps import PYTHON_STEPS, PythonController, running
from .stages import COLUMNS, SeriesColumns


def steps_of(state_type: type) -> ControllerSteps:
    """The ControllerSteps of the kind whose state is `state_type`, from the registry as
    it is now (a kind registered after import included); the kinds without compiled
    steps share PYTHON_STEPS."""
    if state_type is PythonController:
        return PYTHON_STEPS
    steps = _STEPS.get(state_type)
    if steps is None:
        _STEPS.update({component.steps.state_type: component.steps
                       for component in CONTROLLERS.components.values() if component.steps})
        steps = _STEPS[state_type]
    return steps


_STEPS: dict[type, ControllerSteps] = {}  # steps_of's, by the type of their state


def compiled_kinds() -> list[str]:
    """One controller kind for each compiled step (loop.warm() compiles each; the
    kinds without compiled steps share one more)."""
    kinds = {component.steps.state_type: kind
             for kind, component in CONTROLLERS.components.items() if component.steps}
    return sorted(kinds.values())


class LoopInputs(NamedTuple):
    """What every step of a run reads and none changes but at a live change of gains
    (`settings`, between two chunks)."""

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
    mass_column: int           # the controller's outputs the profile reads for its re-plans:
    mass_sigma_column: int     # mass_factor and mass_sigma (-1: none, no re-plans)
    odometry: Any              # the train's sensors and the on-board localisation (None: off)


class LoopState(NamedTuple):
    """Everything a step changes, carried from one chunk of steps to the next: a run
    computed in chunks gives the bits of one computed in a single call."""

    step: int                  # the next step k
    plant: TrainMotion
    profile: ProfileState
    controller: Any            # the controller kind's state NamedTuple
    last: float                # the limiter's last command
    fitness: RunningState
    stood: int                 # samples the train has stood at its last stop (PlantStage's)
    odometry: Any              # OdometryState (None: off)
    ended: bool                # diverged, pruned or arrived: no step follows


FIRST_CHUNK = 64  # steps computed by a run's first call of the loop
CHUNK_SECONDS = 0.05  # wall time each later call aims at: the deadline is checked between calls


def run(profile, plant, controller, prune: tuple[RunningIndex, float] | None,
        check: Callable[[int], None], changes: dict[int, dict[str, float]] | None = None,
        compiled: bool = True):
    """The run of the three stages (built by simulate(), used up by it): (rows (steps x
    len(SERIES)), the controller's outputs (steps x outputs), the horizons), compiled or
    as Python. It runs in chunks of steps, each a call of the loop lasting about
    CHUNK_SECONDS and ending before each step of `changes` (a live change of gains);
    `check(step)` is called before each (simulate() raises there once past its
    deadline)."""
    total, targets = profile.context.steps, profile.targets
    steps = _steps if compiled and AVAILABLE else _steps_source
    schedule = sorted((step, change) for step, change in (changes or {}).items()
                      if 0 <= step < total)
    running_index, limit = prune if prune is not None else (RunningIndex("itae"), math.inf)
    rows = np.empty((total, len(COLUMNS)))
    extras = np.empty((total, len(controller.output_names)))
    located_rows = np.empty((total, len(ODOMETRY_SERIES) if plant.odometry is not None else 0))
    with _controller_seam(controller) as (settings, controller_state):
        inputs = _inputs(profile, plant, controller, settings, running_index, limit, compiled)
        loop = _first_state(profile, plant, controller, controller_state, running_index)
        chunk = FIRST_CHUNK
        while loop.step < total and not loop.ended:
            check(loop.step)
            if loop.profile.request == loop.profile.request:  # the last step asked for it
                inputs, loop = _replanned(profile, inputs, loop)
            if schedule and schedule[0][0] == loop.step:
                inputs, loop = _retuned(controller, inputs, loop, schedule.pop(0)[1])
            stop = min(total, loop.step + chunk, schedule[0][0] if schedule else total)
            started = time.perf_counter()
            loop = steps(inputs, profile.journey, loop, stop, targets, rows, extras,
                         located_rows)
            elapsed = time.perf_counter() - started
            chunk = max(1, min(4 * chunk, int(chunk * CHUNK_SECONDS / max(elapsed, 1e-9))))
    running_index.state = RunningState(*map(float, loop.fitness))
    return (rows[:loop.step], extras[:loop.step], targets[:loop.step],
            located_rows[:loop.step])


@contextmanager
def _controller_seam(stage):
    """(settings, state) the loop steps the stage's controller with: a kind's steps read
    its own; any other kind is called in Python (core/run/python_steps.py)."""
    if stage.component.steps is not None:
        yield stage.controller.settings, stage.controller.state
        return
    with running(stage) as slot:
        yield slot, slot


def _retuned(stage, inputs: LoopInputs, loop: LoopState, change: dict[str, float]
             ) -> tuple[LoopInputs, LoopState]:
    """The inputs and state after a live change of gains before step loop.step:
    ControllerStage.retune rebuilds the controller from its state now; a kind's steps
    then go on with the new settings, a Python controller is the rebuilt one."""
    if stage.component.steps is None:
        stage.retune(change)  # the stage RUNNING holds: its controller is the rebuilt one
        return inputs, loop
    stage.controller.state = loop.controller
    stage.retune(change)
    return (inputs._replace(settings=stage.controller.settings),
            loop._replace(controller=stage.controller.state))


def _replanned(stage, inputs: LoopInputs, loop: LoopState) -> tuple[LoopInputs, LoopState]:
    """The inputs and state after the re-plan the profile's last step asked for:
    ProfileStage.replan, as the profile node makes it after that step."""
    stage.state = loop.profile
    stage.replan()
    return (inputs._replace(profile=inputs.profile._replace(plan=stage.settings.plan)),
            loop._replace(profile=stage.state))


def _inputs(profile, plant, controller, settings, running_index, limit: float,
            compiled: bool) -> LoopInputs:
    train, total = plant.train, profile.context.steps
    # the sensor's draws, as PlantStage.measure takes them (one per step, the same stream)
    draws = plant.rng.standard_normal(total) if plant.noise > 0.0 else np.zeros(total)
    # compiled code reads a line as one array (Python as tuples: faster there)
    line = line_arrays(train.line) if compiled else train.settings.line
    return LoopInputs(
        draws=draws, noise=float(plant.noise), quantum=float(plant.quantum),
        period=float(train.settings.period), train=train.settings._replace(line=line),
        max_speed=float(plant.max_speed), last_stop=plant.last_stop,
        profile=profile.settings._replace(line=line),
        settings=settings, limits=controller.limiter.settings,
        fitness_kind=int(running_index.kind), fitness_limit=float(limit), columns=COLUMNS,
        **estimate_columns(profile, controller), odometry=plant.odometry)


def estimate_columns(profile, controller) -> dict[str, int]:
    """LoopInputs' mass_column and mass_sigma_column: where the controller's outputs hold
    the on-board estimate the profile re-plans from (-1: no re-plans)."""
    names = controller.output_names
    if not profile.settings.replan.enabled:
        return {"mass_column": -1, "mass_sigma_column": -1}
    return {"mass_column": names.index("mass_factor"),
            "mass_sigma_column": names.index("mass_sigma")}


def _first_state(profile, plant, controller, controller_state, running_index) -> LoopState:
    return LoopState(
        step=0, plant=plant.train.motion, profile=profile.state, controller=controller_state,
        last=float(controller.limiter.last), fitness=running_index.state,
        stood=int(plant.stood), odometry=plant.odometry_state, ended=False)


def controller_start(settings, state, target: float, measured: float, horizon):
    """The kind's ControllerSteps.start, chosen by the type of `state`."""
    return steps_of(type(state)).start(settings, state, target, measured, horizon)


def controller_step(settings, state, target: float, measured: float, horizon, last: float,
                    limits: LimiterSettings):
    """The kind's ControllerSteps.step, chosen by the type of `state`."""
    return steps_of(type(state)).step(settings, state, target, measured, horizon, last, limits)


def as_read(horizon):
    """A horizon as the controllers read it: in Python a list of floats (numpy's scalars
    differ from floats in places: a bool's subtraction), in compiled code the array."""
    return horizon.tolist()


if AVAILABLE:  # in compiled code the kind's function is chosen while compiling
    @overload(controller_start)
    def _compiled_start(settings, state, target, measured, horizon):
        start = steps_of(state.instance_class).start
        return lambda settings, state, target, measured, horizon: start(
            settings, state, target, measured, horizon)

    @overload(controller_step)
    def _compiled_step(settings, state, target, measured, horizon, last, limits):
        step = steps_of(state.instance_class).step
        return lambda settings, state, target, measured, horizon, last, limits: step(
            settings, state, target, measured, horizon, last, limits)

    @overload(as_read)
    def _compiled_as_read(horizon):
        return lambda horizon: horizon


def _steps_source(inputs: LoopInputs, journey: JourneyTable | None, loop: LoopState,
                  stop: int, targets, rows, extras, located_rows) -> LoopState:
    """The loop from step loop.step up to `stop` (or the step the run ends at); the state
    after. `targets` holds every step's horizon: given (time-indexed plans) or filled in
    LOOKAHEAD steps ahead by the profile's step."""
    k, plant, profile, controller, last, fitness, stood, odometry = (
        loop.step, loop.plant, loop.profile, loop.controller, loop.last, loop.fitness,
        loop.stood, loop.odometry)
    ended = False
    while k < stop and not ended and profile.request != profile.request:  # NaN: no re-plan
        measured = float(sensor_reading(plant.speed, inputs.draws[k], inputs.noise,
                                        inputs.quantum))
        odometry, position, speed = located(inputs.odometry, odometry, k, inputs.train, plant,
                                            located_rows[k])
        if position == position:  # located (PlantStage.outputs)
            measured = speed
        else:
            position = plant.position  # and the speed NaN: the profile's is its travel
        mass, mass_sigma = math.nan, math.nan
        if k > 0 and inputs.mass_column >= 0:  # the estimate after step k - 1
            mass = extras[k - 1, inputs.mass_column]
            mass_sigma = extras[k - 1, inputs.mass_sigma_column]
        profile = profile_step(inputs.profile, journey, profile, k, position, speed,
                               targets, mass, mass_sigma, adhesion_seen(odometry))
        horizon = targets[k]
        target = float(horizon[0])
        if k == 0:
            controller = controller_start(inputs.settings, controller, target, measured,
                                          as_read(horizon))
        if inputs.limits.slip_hold:  # ControllerStage.run_ready_steps
            last = held_at_rail(last, drive_effort(inputs.train, plant),
                                inputs.limits.max_change)
        u, outputs, controller = controller_step(inputs.settings, controller, target,
                                                 measured, as_read(horizon), last, inputs.limits)
        last = u
        _record(inputs, journey, rows[k], k, plant, position, target, measured, u)
        for i in range(len(outputs)):
            extras[k, i] = outputs[i]
        speed = plant.speed
        stood = standing(inputs.last_stop, stood, plant.position, speed)  # PlantStage.apply
        before, plant = plant, train_step(inputs.train, plant, u)
        odometry = odometer_moved(inputs.odometry, odometry, inputs.train, before, plant)
        if diverged(plant.speed, inputs.max_speed):
            ended = True
        else:
            fitness = running_step(inputs.fitness_kind, fitness, k * inputs.period,
                                   horizon[0] - speed)
            ended = fitness.value > inputs.fitness_limit or held(inputs.last_stop, stood)
        k += 1
    return LoopState(k, plant, profile, controller, last, fitness, stood, odometry, ended)


@jitable(inline=True)
def _record(inputs: LoopInputs, journey: JourneyTable | None, row, k: int, plant: TrainMotion,
            position: float, target: float, measured: float, command: float) -> None:
    """Step k's row of the SERIES (PlantStage.outputs at t_k, the target and command; the
    speed limit where the profile has the train, at `position`)."""
    column = inputs.columns
    acceleration, disturbance, resistance, line_resistance = train_outputs(inputs.train, plant)
    row[column.t], row[column.target], row[column.position] = (k * inputs.period, target,
                                                               plant.position)
    row[column.measured_speed], row[column.speed] = measured, plant.speed
    row[column.acceleration], row[column.disturbance] = acceleration, disturbance
    row[column.force], row[column.resistance] = plant.force, resistance
    row[column.line_resistance] = line_resistance
    row[column.speed_limit] = plan_speed_limit(inputs.profile, journey, position)
    row[column.command] = command


def _loop_sources(signature: tuple) -> Sources:
    """What the loop's `signature` compiles in besides the loop's modules and their
    imports: the modules of the controller kind whose state its LoopState holds (its
    steps', its state's, its factory's), wherever they live; every other kind's modules are
    kept apart (a kind's code enters its own signatures only, through the registry)."""
    loop = next(argument for argument in signature
                if getattr(argument, "instance_class", None) is LoopState)
    state = loop.types[LoopState._fields.index("controller")].instance_class
    kinds = {kind: component for kind, component in CONTROLLERS.components.items()
             if component.steps and component.steps.state_type is state}
    own = _modules_of(steps_of(state), *kinds.values())
    apart = set().union(*map(_modules_of, CONTROLLERS.components.values())) - own
    journey = (", a journey's" if any(getattr(argument, "instance_class", None) is JourneyTable
                                      for argument in signature) else "")
    what = (f"the loop for controller {', '.join(sorted(kinds))}{journey}" if kinds else
            f"the loop for the controllers without compiled steps{journey}")
    return Sources(what, tuple(sorted(own)), frozenset(apart))


def _modules_of(*parts) -> set[str]:
    """The modules of a kind's ControllerSteps or registry entry (factory, steps, state)."""
    found = set()
    for part in parts:
        steps = getattr(part, "steps", part)
        for code in (getattr(part, "factory", None), *(steps or ())):
            found.add(getattr(code, "__module__", None))
    return found - {None}


_steps = compiled(_steps_source, _loop_sources)
