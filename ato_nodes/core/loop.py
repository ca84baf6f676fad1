"""The lockstep loop's three stages, built from parameters, ROS-free.

Step k (t_k = k * period), in every runner:
  plant.outputs()           -> position s_k, measured and true speed, ... at t_k
  profile.on_position(s_k)  -> the target of the NEXT step, r_k+1 (and r_0 at k = 0)
  controller.step(r_k, y_k) -> command u_k (N/kN) and observer states
  plant.apply(u_k)          -> integrate [t_k, t_k+1] with u_k held
The profile works one step ahead, from the position extrapolated to t_k+1
(2 s_k - s_k-1; error ~ a dt^2, millimetres), so it runs beside the
controller instead of in front of it: the critical path of a step is two
message hops (plant -> controller -> plant), not three. For time-indexed
curves the targets are exactly r(t_k).

The ROS nodes run one stage each and pass the values as float64 messages,
bit for bit; `simulate()` makes the same calls in one process, so both give
identical numbers.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from .adrc import ControllerOutput, HanADRC, HanADRCGains, LinearADRC, LinearADRCGains
from .params import steps
from .plant import PointMassTrain, TrainParameters, TrainState
from .profiles import Seed000Profile, StepProfile, TableProfile


class ProfileStage:
    def __init__(self, values: dict[str, Any]):
        self.period = values["run.period"]
        self.total_steps = steps(values)
        self.received = 0
        self.last_position = 0.0
        kind = values["profile.kind"]
        if kind == "seed000":
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
        targets = [self.curve.speed(0.0, position)] if k == 0 else []
        if k + 1 < self.total_steps:
            predicted = 2.0 * position - self.last_position if k > 0 else position
            targets.append(self.curve.speed((k + 1) * self.period, predicted))
        self.last_position = position
        return targets


@dataclass
class PlantOutputs:
    position: float      # m
    measured_speed: float  # m/s, what the speed sensor reports
    speed: float         # m/s, true
    acceleration: float  # m/s^2, true, at t_k- (under the previous command)
    disturbance: float   # m/s^2, phi(t_k)
    force: float         # N/kN applied
    resistance: float    # N/kN basic resistance w0


class PlantStage:
    def __init__(self, values: dict[str, Any]):
        self.params = TrainParameters(
            gamma=values["plant.gamma"], gravity=values["plant.gravity"],
            davis_a=values["plant.davis_a"], davis_b=values["plant.davis_b"],
            davis_c=values["plant.davis_c"], mass=values["plant.mass"],
            disturbance_amplitude=values["plant.disturbance.amplitude"],
            disturbance_frequency=values["plant.disturbance.frequency"],
            disturbance_phase=values["plant.disturbance.phase"],
            actuator_lag=values["plant.actuator_lag"],
            **({"max_traction_force": values["plant.max_traction_force"],
                "max_traction_power": values["plant.max_traction_power"],
                "max_brake_force": values["plant.max_brake_force"],
                "max_brake_power": values["plant.max_brake_power"]}
               if values["plant.envelope"] else {}))
        self.train = PointMassTrain(
            self.params, values["run.period"], values["plant.substeps"],
            TrainState(position=values["plant.initial_position"],
                       speed=values["plant.initial_speed"]))
        self.last_command = 0.0

    def outputs(self) -> PlantOutputs:
        s, p = self.train.state, self.params
        return PlantOutputs(s.position, s.speed, s.speed, self.train.acceleration(self.last_command),
                            p.disturbance(s.time), s.force, p.resistance(s.speed))

    def apply(self, command: float) -> None:
        self.last_command = command
        self.train.step(command)


class ControllerStage:
    def __init__(self, values: dict[str, Any], initial_target: float, initial_speed: float):
        period = values["run.period"]
        limits = values["controller.u_min"], values["controller.u_max"]
        if values["controller.kind"] == "han_adrc":
            gains = HanADRCGains(**{name: values[f"adrc.{name}"] for name in (
                "mu1", "mu2", "alpha1", "alpha2", "r0", "h0", "beta1", "beta2", "beta3", "b0",
                "delta", "implicit_nlsef")})
            self.controller = HanADRC(gains, period, *limits, initial_target=initial_target,
                                      initial_speed=initial_speed)
        else:
            gains = LinearADRCGains(values["ladrc.omega_o"], values["ladrc.omega_c"],
                                    values["ladrc.b0"])
            self.controller = LinearADRC(gains, period, *limits, initial_speed=initial_speed)

    def step(self, target: float, measured_speed: float) -> ControllerOutput:
        return self.controller.step(target, measured_speed)


SERIES = ("t", "target", "position", "measured_speed", "speed", "acceleration", "disturbance",
          "force", "resistance", "command", "z1", "z2", "z3", "v1", "v2")


def simulate(values: dict[str, Any]) -> dict[str, np.ndarray]:
    """Run the loop in this process; one array per SERIES name, one entry per step."""
    period = values["run.period"]
    profile, plant = ProfileStage(values), PlantStage(values)
    controller = None
    targets: deque[float] = deque()
    rows = []
    for k in range(steps(values)):
        out = plant.outputs()
        targets.extend(profile.on_position(out.position))
        target = targets.popleft()
        if controller is None:
            controller = ControllerStage(values, target, out.measured_speed)
        c = controller.step(target, out.measured_speed)
        plant.apply(c.u)
        rows.append((k * period, target, out.position, out.measured_speed, out.speed,
                     out.acceleration, out.disturbance, out.force, out.resistance,
                     c.u, c.z1, c.z2, c.z3, c.v1, c.v2))
    table = np.array(rows, dtype=float).reshape(-1, len(SERIES))
    return {name: table[:, i] for i, name in enumerate(SERIES)}
