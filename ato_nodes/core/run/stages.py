"""The lockstep loop's three stages, built from parameters, ROS-free.

Step k (t_k = k * period), in every runner:
  plant.outputs()            -> position s_k, measured and true speed, ... at t_k
  profile.on_position(s_k)   -> the horizon of step k+2: r_k+2 .. r_k+2+N, N = controller.preview
                                (and the horizons of steps 0, 1, 2 at k = 0)
  controller.step(r_k, y_k, horizon_k) -> command u_k (N/kN)
  plant.apply(u_k)           -> integrate [t_k, t_k+1] with u_k held
The target topic carries r_k as its k-th message, whatever the runner, so the
recorded target of step k is always r(t_k). The profile sends targets two
steps ahead, from the position extrapolated to t_k+2 (s_k + 2 (s_k - s_k-1);
error ~ a (2 dt)^2, centimetres; exact for time-indexed curves), so it runs
beside the controller instead of in front of it: the critical path of a step
is two message hops (plant -> controller -> plant). Beyond r_k+2 the horizon is
the plan (the run context's preview): exact for time-indexed targets, along
the planned trajectory for position-indexed ones.

Each stage is built when its node starts, from exactly the values the node
declares (schema.NodeValues) and the run context, and holds the settings and state
of its step functions (the train's, the profile's, the controller kind's); the ROS
nodes call one stage each, a step at a time, and pass the values as float64
messages, bit for bit; `simulate()` runs the same step functions in the one loop of
core/run/fast_loop.py, so both give identical numbers (tests/test_stages.py drives
the stages as the nodes do).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from collections import deque
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..base.errors import ScenarioError
from ..config.components import CONTROLLERS
from ..config.context import RunContext, ato_train
from ..config.schema import NodeValues, steps
from ..control.limiter import CommandLimiter, held_at_rail
from ..targets.horizons import LOOKAHEAD, plan_speed_limit, profile_start, profile_step
from ..targets.replan import CurveReplan, degraded_plan, replanned_table
from ..train.line import Line
from ..train.lines import line_of
from ..train.plant import (PointMassTrain, TrainParameters, TrainState, diverged,
                           drive_effort, sensor_reading, train_outputs)
from ..train.adhesion import adhesion_of
from .last_stop import held, last_stop, standing
from .located import ODOMETRY_SERIES, located, odometer_moved, odometry_of

# The series of a run, one value per step, in the order of simulate()'s rows.
SERIES = ("t", "target", "position", "measured_speed", "speed", "acceleration", "disturbance",
          "force", "resistance", "line_resistance", "speed_limit", "command")
# Each series' column in those rows, by name (the compiled loop writes them so).
SeriesColumns = NamedTuple("SeriesColumns", [(name, int) for name in SERIES])
COLUMNS = SeriesColumns(*range(len(SERIES)))


class ProfileStage:
    """Target horizons (LOOKAHEAD steps ahead) and the speed limit from each step's
    position: a holder of the profile step's settings and state
    (core/targets/horizons.py) and of the horizons (steps x (N + 1); a time-indexed
    plan's computed once per plan)."""

    def __init__(self, values: dict[str, Any], line: Line | None = None):
        self.context = RunContext(values, line)
        # built now: a bad table, plan or line fails at start-up (the berth where it cannot
        # apply too)
        self.settings = self.context.profile_settings
        self.period = values["run.period"]
        self.total_steps = steps(values)
        self.journey = getattr(self.context.plan, "journey", None)
        self.state = profile_start(max(self.context.planned_mass, 1.0))
        self.replans: list[CurveReplan] = []  # mid-run re-plans (core/targets/replan.py)
        self.targets = (np.empty((self.total_steps, self.settings.preview + 1))
                        if self.settings.position_indexed else time_horizons(self.context).copy())
        self.received = 0

    def on_position(self, position: float, mass: float = math.nan,
                    mass_sigma: float = math.nan, adhesion: float = math.nan,
                    located_speed: float = math.nan) -> list[list[float]]:
        """Position s_k of step k in (and the on-board mass estimate after step k - 1, for
        profile.replan; the adhesion seen by step k, for profile.degraded; the located
        speed then, NaN without odometry: horizons.profile_step); the horizons to
        publish now out, in step order (horizons.profile_step), the plan re-made after it
        if the step asked."""
        k = self.received
        self.received += 1
        self.state = profile_step(self.settings, self.journey, self.state, k, position,
                                  located_speed, self.targets, mass, mass_sigma, adhesion)
        if self.state.request == self.state.request:
            self.replan()
        if self.journey is not None:  # the plan's state and re-plans, for the node to say
            self.context.plan.moved(k * self.period, self.state.journey)
        first = 0 if k == 0 else k + LOOKAHEAD
        return self.targets[first:k + LOOKAHEAD + 1].tolist()

    def replan(self) -> None:
        """The re-plan the last step asked for (core/targets/replan.py): the plan's table
        re-made from the train's state then, for the mass and within the adhesion asked;
        the state keeps it."""
        state, values = self.state, self.context.values
        train, forces = ato_train(values, state.request), (math.inf, math.inf)
        if state.request_adhesion < math.inf:
            values, train, *forces = degraded_plan(values, train, state.request_adhesion,
                                                   self.settings.plan)
        table = replanned_table(values, self.context.line, train, self.settings.plan,
                                state.last_position, state.request_speed, state.replanned_at)
        self.settings = self.settings._replace(plan=table)
        self.replans.append(CurveReplan(state.replanned_at, state.last_position,
                                        state.request_speed, state.request, state.planned_mass,
                                        state.request_adhesion, *forces))
        self.state = state._replace(planned_mass=state.request, request=math.nan,
                                    request_speed=math.nan,
                                    planned_adhesion=state.request_adhesion,
                                    request_adhesion=math.nan)

    def speed_limit(self, position: float) -> float:
        """The limit that applies at step k's position, m/s (inf without a line): the
        plan's own belt limit where it has one (the ATO curve's tail rule)."""
        return float(plan_speed_limit(self.settings, self.journey, position))


@functools.lru_cache(maxsize=4)
def _time_horizons(profile_values: str) -> np.ndarray:
    context = RunContext(NodeValues("profile", json.loads(profile_values)))
    plan, period, preview = context.plan, context.period, context.values["controller.preview"]
    # A step's horizon holds the targets at t_k .. t_k+N, exactly as RunContext.horizon
    # computes them for a time-indexed plan: each time's target once, then windows of it.
    targets = np.array([plan.speed(j * period, 0.0) for j in range(context.steps + preview)],
                       dtype=float)
    windows = np.lib.stride_tricks.sliding_window_view(targets, preview + 1)
    return windows[:context.steps].copy()


def time_horizons(context: RunContext) -> np.ndarray:
    """Every step's horizon (steps x (N + 1)) of a time-indexed plan, computed once per
    process and plan (read-only: shared by every run of the plan)."""
    table = _time_horizons(json.dumps(dict(context.values), sort_keys=True))
    table.flags.writeable = False
    return table


@dataclass(slots=True)
class PlantOutputs:
    position: float      # m
    measured_speed: float  # m/s, what the speed sensor reports
    speed: float         # m/s, true
    acceleration: float  # m/s^2, true, at t_k- (under the previous command)
    disturbance: float   # m/s^2, phi(t_k)
    force: float         # N/kN applied
    resistance: float    # N/kN basic resistance w0
    line_resistance: float  # N/kN gradient + curve + tunnel resistance of the belt
    located_position: float  # m, where the ATO has the train (the true position without
    odometry: list[float]    # odometry); ODOMETRY_SERIES' values (empty without)
    drive_effort: float      # N/kN the rail gives while the wheels slip or slide (NaN while
                             # they roll, or without controller.slip_hold)


class PlantStage:
    """The train, its line and its speed sensor (noise and quantisation, seeded); and
    the end of a journey's run at its last stop (core/run/last_stop.py)."""

    def __init__(self, values: dict[str, Any], line: Line | None = None):
        nominal = TrainParameters.from_values(values)  # what the ATO knows; the real train:
        loaded = nominal.loaded(values["plant.mass_factor"], values["plant.davis_absolute"])
        factor = values["plant.resistance_factor"]
        self.params = dataclasses.replace(
            loaded, adhesion=adhesion_of(values),
            actuator_lag=values["plant.lag_factor"] * nominal.actuator_lag,
            **{name: factor * getattr(loaded, name) for name in ("davis_a", "davis_b",
                                                                  "davis_c")})
        if line is None:
            line = line_of(values)
        self.train = PointMassTrain(
            self.params, values["run.period"], values["plant.substeps"],
            TrainState(position=values["plant.initial_position"],
                       speed=values["plant.initial_speed"]), line)
        self.max_speed = values["plant.max_speed"]
        self.slip_hold = values["controller.slip_hold"]  # the drive's effort published
        self.noise = values["plant.speed_noise"]
        self.quantum = values["plant.speed_quantum"]
        self.rng = np.random.default_rng(values["plant.noise_seed"])
        self.odometry, self.odometry_state = odometry_of(values, line, steps(values))
        self.last_stop = last_stop(values)
        self.stood = 0  # samples the train has stood at its last stop, to the last applied

    @property
    def diverged(self) -> bool:
        """Speed not finite or beyond plant.max_speed: a run that can only get worse."""
        return diverged(self.train.motion.speed, self.max_speed)

    @property
    def arrived(self) -> bool:
        """The train has stood run.last_stop_hold at its journey's last stop: the run
        ends with the step just applied."""
        return held(self.last_stop, self.stood)

    def measure(self, speed: float) -> float:
        """What the speed sensor reports: speed plus noise, to its resolution."""
        draw = self.rng.standard_normal() if self.noise > 0.0 else 0.0
        return sensor_reading(speed, draw, self.noise, self.quantum)

    def outputs(self) -> PlantOutputs:
        """Step k's (called once a step, before apply): the sensors read, the located
        position and speed with odometry (core/run/located.py)."""
        motion = self.train.motion
        acceleration, disturbance, resistance, line_resistance = train_outputs(
            self.train.settings, motion)
        measured, position, row = self.measure(motion.speed), motion.position, []
        if self.odometry is not None:
            values = np.empty(len(ODOMETRY_SERIES))
            self.odometry_state, position, measured = located(
                self.odometry, self.odometry_state, motion.steps, self.train.settings,
                motion, values)
            row = values.tolist()
        return PlantOutputs(motion.position, measured, motion.speed, acceleration,
                            disturbance, motion.force, resistance, line_resistance, position,
                            row, drive_effort(self.train.settings, motion)
                            if self.slip_hold else math.nan)

    def apply(self, command: float) -> None:
        state = self.train.state  # step k's, as its outputs gave it
        self.stood = standing(self.last_stop, self.stood, state.position, state.speed)
        before = self.train.motion
        self.train.step(command)
        self.odometry_state = odometer_moved(self.odometry, self.odometry_state,
                                             self.train.settings, before, self.train.motion)


class ControllerStage:
    """The controller (built at once from the registry) and its pairing rule: step k
    needs the measured speed y_k and the horizon r_k .. r_k+N; it is given r_k (the
    horizon's first) as its target and the horizon, as the compiled loop gives them.

    Live parameters (the controller kind's `live_parameters`): changes put in
    `pending` take effect at the next step boundary, before the next step is
    computed; `applied` lists them as (step, changes), step being the first one
    computed with them. The node fills `pending` from `ros2 param set`; simulate()'s
    loop (core/run/fast_loop.py) calls `retune` at the step of each of a run's recorded
    changes and goes on with the new settings, so both give the same numbers."""

    def __init__(self, values: dict[str, Any], line: Line | None = None):
        self.values = values
        self.component = CONTROLLERS.chosen(values)
        self.context = RunContext(values, line)
        self.limiter = CommandLimiter.from_values(values)
        self.controller = self.component.factory(values, self.context, self.limiter)
        self.horizons: deque[list[float]] = deque()
        self.speeds: deque[float] = deque()
        # with controller.slip_hold, the drive's effort of each step (PlantOutputs')
        self.efforts: deque[float] | None = deque() if values["controller.slip_hold"] else None
        self.step_index = 0
        self.pending: dict[str, float] = {}
        self.applied: list[tuple[int, dict[str, float]]] = []

    @property
    def output_names(self) -> tuple[str, ...]:
        return self.component.output_names

    def retune(self, changes: dict[str, float]) -> None:
        """Rebuild the controller with `changes` to its live parameters, carrying its
        state (the kind's `state_paths`) and the limiter's over: the run goes on as if
        the new values had been set between two steps."""
        live = self.component.live_parameters
        refused = sorted(set(changes) - set(live))
        if refused:
            raise ScenarioError(f"{refused[0]} cannot change during a run (live parameters "
                                f"of {self.component.kind}: {', '.join(live) or 'none'})")
        values = type(self.values)(self.values.node, {**self.values, **changes}) \
            if isinstance(self.values, NodeValues) else {**self.values, **changes}
        rebuilt = self.component.factory(values, self.context, self.limiter)
        for path in self.component.state_paths:
            *owners, name = path.split(".")
            old, new = self.controller, rebuilt
            for owner in owners:
                old, new = getattr(old, owner), getattr(new, owner)
            setattr(new, name, getattr(old, name))
        self.controller, self.values = rebuilt, values

    def run_ready_steps(self) -> list:
        """Run every step whose inputs have all arrived; their outputs in order."""
        outputs = []
        while self.speeds and self.horizons and (self.efforts is None or self.efforts):
            if self.pending:
                self.retune(self.pending)
                self.applied.append((self.step_index, self.pending))
                self.pending = {}
            horizon = self.horizons.popleft()
            speed = self.speeds.popleft()
            if self.efforts is not None:
                self.limiter.last = held_at_rail(self.limiter.last, self.efforts.popleft(),
                                                 self.limiter.max_change)
            if self.step_index == 0:
                self.controller.start(horizon[0], speed, horizon)
            outputs.append(self.controller.step(horizon[0], speed, horizon))
            self.step_index += 1
        return outputs
