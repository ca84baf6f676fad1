"""The lockstep loop's three stages, built from parameters, ROS-free.

Step k (t_k = k * period), in every runner:
  plant.outputs()            -> position s_k, measured and true speed, ... at t_k
  profile.on_position(s_k)   -> target r_k+2 (and r_0, r_1, r_2 at k = 0)
  controller.step(r, y_k)    -> command u_k (N/kN); r = r_k+p with p = controller.preview
  plant.apply(u_k)           -> integrate [t_k, t_k+1] with u_k held
The target topic carries r_k as its k-th message, whatever the runner, so the
recorded target of step k is always r(t_k). The profile sends targets two
steps ahead, from the position extrapolated to t_k+2 (s_k + 2 (s_k - s_k-1);
error ~ a (2 dt)^2, centimetres; exact for time-indexed curves), so it runs
beside the controller instead of in front of it: the critical path of a step
is two message hops (plant -> controller -> plant), and the controller can
look one step ahead (preview = 1: its reference is the target for the end
of the interval its command acts over, as the ATO knows its planned curve).

The ROS nodes run one stage each and pass the values as float64 messages,
bit for bit; `simulate()` makes the same calls in one process, so both give
identical numbers.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from .adrc import (CommandLimiter, ControllerOutput, DiscreteADRC, DiscreteADRCGains, HanADRC,
                   HanADRCGains, LinearADRC, LinearADRCGains, nladrc_gains)
from .line import load_line
from .params import steps
from .plant import PointMassTrain, TrainParameters, TrainState
from .profiles import AtoCurve, Seed000Profile, StepProfile, TableProfile, ato_curve


LOOKAHEAD = 2  # steps the profile runs ahead of the plant


class ProfileStage:
    """Targets (LOOKAHEAD steps ahead) and the speed limit from each step's position."""

    def __init__(self, values: dict[str, Any]):
        self.period = values["run.period"]
        self.total_steps = steps(values)
        self.received = 0
        self.last_position = 0.0
        self.approach_step = values["profile.approach_step"]
        self.stair: float | None = None
        kind = values["profile.kind"]
        self.line = load_line(values["line.file"]) if values["line.file"] else None
        if kind == "ato":
            self.curve = ato_curve(values, self.line)
        elif kind == "seed000":
            self.curve = Seed000Profile(
                period=values["profile.seed000.cycle"], v_inc=values["profile.seed000.v_inc"],
                t1=values["profile.seed000.t1"], cruise_high=values["profile.seed000.cruise_high"],
                cruise_low=values["profile.seed000.cruise_low"])
        elif kind == "step":
            self.curve = StepProfile(values["profile.step.speed"], values["profile.step.time"])
        else:
            self.curve = TableProfile.from_csv(values["profile.table.file"])

    def on_position(self, position: float) -> list[float]:
        """Position s_k of step k in; the targets to publish now out, in step order."""
        k = self.received
        self.received += 1
        travel = position - self.last_position if k else 0.0  # over the last step
        if k == 0:
            wanted = [(step, position) for step in range(LOOKAHEAD + 1)]
        else:
            wanted = [(k + LOOKAHEAD, position + LOOKAHEAD * travel)]
        speed = travel / self.period
        self.last_position = position
        return [self.approach(self.curve.speed(step * self.period, predicted), speed)
                for step, predicted in wanted if step < self.total_steps]

    def approach(self, target: float, speed: float) -> float:
        """Seed 003's stepped approach: while the target is more than one step above
        the speed, the published target is a stair one step above the speed, held
        until the train is within a quarter step of it. Only upwards: a target below
        the speed is a braking curve protecting a limit or the stop, never softened."""
        step = self.approach_step
        if step <= 0.0 or target - speed <= step:
            self.stair = None
            return target
        if self.stair is None or abs(self.stair - speed) < step / 4:
            self.stair = speed + step
        return min(self.stair, target)  # a stair held while the target fell stays under it

    def speed_limit(self, position: float) -> float:
        """The limit that applies at step k's position, m/s (inf without a line)."""
        if isinstance(self.curve, AtoCurve):
            return self.curve.limit(position)
        return self.line.speed_limit(position) if self.line is not None else math.inf


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


class PlantStage:
    """The train, its line and its speed sensor (noise and quantisation, seeded)."""

    def __init__(self, values: dict[str, Any]):
        self.params = TrainParameters(
            gamma=values["plant.gamma"], gravity=values["plant.gravity"],
            davis_a=values["plant.davis_a"], davis_b=values["plant.davis_b"],
            davis_c=values["plant.davis_c"], mass=values["plant.mass"],
            disturbance_amplitude=values["plant.disturbance.amplitude"],
            disturbance_frequency=values["plant.disturbance.frequency"],
            disturbance_phase=values["plant.disturbance.phase"],
            actuator_lag=values["plant.actuator_lag"], dead_time=values["plant.dead_time"],
            length=values["plant.length"], pantograph_offset=values["plant.pantograph_offset"],
            hold_at_standstill=values["plant.hold_at_standstill"],
            **({"max_traction_force": values["plant.max_traction_force"],
                "max_traction_power": values["plant.max_traction_power"],
                "max_brake_force": values["plant.max_brake_force"],
                "max_brake_power": values["plant.max_brake_power"]}
               if values["plant.envelope"] else {}))
        self.train = PointMassTrain(
            self.params, values["run.period"], values["plant.substeps"],
            TrainState(position=values["plant.initial_position"],
                       speed=values["plant.initial_speed"]),
            load_line(values["line.file"]) if values["line.file"] else None)
        self.max_speed = values["plant.max_speed"]
        self.noise = values["plant.speed_noise"]
        self.quantum = values["plant.speed_quantum"]
        self.rng = np.random.default_rng(values["plant.noise_seed"])

    @property
    def diverged(self) -> bool:
        """Speed not finite or beyond plant.max_speed: a run that can only get worse."""
        speed = self.train.state.speed
        return not (abs(speed) <= self.max_speed)  # also true for NaN

    def measure(self, speed: float) -> float:
        """What the speed sensor reports: speed plus noise, to its resolution."""
        if self.noise > 0.0:
            speed += self.noise * self.rng.standard_normal()
        if self.quantum > 0.0:
            speed = self.quantum * round(speed / self.quantum)
        return speed

    def outputs(self) -> PlantOutputs:
        s, p, train = self.train.state, self.params, self.train
        return PlantOutputs(s.position, self.measure(s.speed), s.speed, train.acceleration(),
                            p.disturbance(s.time), s.force, p.resistance(s.speed),
                            train.line_resistance())

    def apply(self, command: float) -> None:
        self.train.step(command)


class ControllerStage:
    """The controller and its pairing rule: step k needs the measured speed y_k and
    the targets up to r_k+preview (r_N-1 at most)."""

    def __init__(self, values: dict[str, Any]):
        self.values = values
        self.preview = values["controller.preview"]
        self.total_steps = steps(values)
        self.targets: deque[float] = deque()
        self.speeds: deque[float] = deque()
        self.step_index = 0
        self.controller: HanADRC | DiscreteADRC | LinearADRC | None = None

    def _build(self, initial_target: float, initial_speed: float):
        values = self.values
        period = values["run.period"]
        limiter = CommandLimiter(values["controller.u_min"], values["controller.u_max"], period,
                                 values["controller.max_rate"], values["controller.mode_band"],
                                 values["controller.holding_brake"])
        kind = values["controller.kind"]
        if kind == "linear_adrc":
            gains = LinearADRCGains(values["ladrc.omega_o"], values["ladrc.omega_c"],
                                    values["ladrc.b0"])
            return LinearADRC(gains, period, limiter, initial_speed=initial_speed)
        if kind == "discrete_adrc":
            controller, gains = DiscreteADRC, DiscreteADRCGains(**{
                name: values[f"dadrc.{name}"] for name in DiscreteADRCGains.__dataclass_fields__})
        elif kind == "nladrc":
            controller, gains = HanADRC, nladrc_gains(
                **{name: values[f"nladrc.{name}"] for name in (
                    "kp", "kd", "omega", "b", "alpha1", "alpha2", "r0", "h0")},
                delta=values["nladrc.delta"])
        else:
            controller, gains = HanADRC, HanADRCGains(**{name: values[f"adrc.{name}"] for name in (
                "mu1", "mu2", "alpha1", "alpha2", "r0", "h0", "beta1", "beta2", "beta3", "b0",
                "delta", "implicit_nlsef")})
        return controller(gains, period, limiter, initial_target=initial_target,
                          initial_speed=initial_speed)

    def ready(self) -> list[ControllerOutput]:
        """Run every step whose inputs have all arrived; their outputs in order."""
        outputs = []
        while self.speeds:
            lead = min(self.preview, self.total_steps - 1 - self.step_index)
            if len(self.targets) <= lead:
                break
            reference = self.targets[lead]
            speed = self.speeds.popleft()
            self.targets.popleft()
            if self.controller is None:
                self.controller = self._build(reference, speed)
            outputs.append(self.controller.step(reference, speed))
            self.step_index += 1
        return outputs


SERIES = ("t", "target", "position", "measured_speed", "speed", "acceleration", "disturbance",
          "force", "resistance", "line_resistance", "speed_limit", "command", "z1", "z2", "z3",
          "v1", "v2")


def simulate(values: dict[str, Any]) -> dict[str, np.ndarray]:
    """Run the loop in this process; one array per SERIES name, one entry per step.
    A diverged run (see PlantStage.diverged) ends early, as it does in the stack."""
    period = values["run.period"]
    profile, plant, controller = ProfileStage(values), PlantStage(values), ControllerStage(values)
    rows = []
    for k in range(steps(values)):
        out = plant.outputs()
        controller.targets.extend(profile.on_position(out.position))
        target = controller.targets[0]
        controller.speeds.append(out.measured_speed)
        (c,) = controller.ready()
        plant.apply(c.u)
        rows.append((k * period, target, out.position, out.measured_speed, out.speed,
                     out.acceleration, out.disturbance, out.force, out.resistance,
                     out.line_resistance, profile.speed_limit(out.position),
                     c.u, c.z1, c.z2, c.z3, c.v1, c.v2))
        if plant.diverged:
            break
    table = np.array(rows, dtype=float).reshape(-1, len(SERIES))
    return {name: table[:, i] for i, name in enumerate(SERIES)}
