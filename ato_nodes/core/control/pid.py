"""PID speed controller: the industrial baseline every comparison needs (ROS-free).

    u = ff + kp e + I + D,   e = r - y   (N/kN; r the tracked target, y the measured speed)

* feedforward, weighted by `feedforward` (0 off, 1 full): the command the nominal
  train (the run context's model) needs to follow the plan, a_r / xi + w0(r), with
  a_r the planned acceleration at the tracked target from the preview horizon,
  (r_k+N - r_k+N-1) / h (0 without preview);
* derivative on the measurement, not on the error (a target step gives no kick),
  through a first-order filter of time constant `tf` (backward Euler);
* integral with back-calculation anti-windup: while the limiter cuts the command,
  the integrator is driven back at rate `kt` (1/s) times the cut, so it does not
  wind up at saturation, a jerk limit or a neutral section.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..base.registry import Component, Controller, ControllerOutput, Output
from ..base.spec import param, settings
from .limiter import CommandLimiter

PARAMETERS = (
    param("pid.kp", 50.0, "PID proportional gain, N/kN per m/s", "controller", 0.0, 1e6),
    param("pid.ki", 5.0, "PID integral gain, N/kN per m", "controller", 0.0, 1e6),
    param("pid.kd", 0.0, "PID derivative gain (on the filtered measurement), N/kN per m/s^2",
          "controller", 0.0, 1e6),
    param("pid.tf", 0.2, "PID derivative filter time constant, s", "controller", 0.0, 100.0),
    param("pid.kt", 1.0, "PID anti-windup back-calculation rate, 1/s", "controller", 0.0, 1e4),
    param("pid.feedforward", 1.0, "weight of the nominal-model feedforward (planned "
          "acceleration and basic resistance), 0 = off", "controller", 0.0, 2.0),
)


@dataclass(frozen=True)
class PIDGains:
    kp: float
    ki: float
    kd: float
    tf: float
    kt: float
    feedforward: float


class PID(Controller):
    def __init__(self, gains: PIDGains, period: float, limiter: CommandLimiter, train):
        self.g, self.h, self.limiter, self.train = gains, period, limiter, train
        self.integral = 0.0
        self.filtered = 0.0

    def start(self, target: float, measured: float) -> None:
        self.filtered = measured

    def step(self, target: float, measured: float, horizon) -> ControllerOutput:
        g, h, train = self.g, self.h, self.train
        planned_acceleration = (horizon[-1] - horizon[-2]) / h if len(horizon) > 1 else 0.0
        feedforward = g.feedforward * (planned_acceleration / train.xi + train.resistance(target))
        previous = self.filtered
        self.filtered += h / (g.tf + h) * (measured - previous)
        derivative = -g.kd * (self.filtered - previous) / h
        error = target - measured
        proportional = g.kp * error
        raw = feedforward + proportional + self.integral + derivative
        u = self.limiter.apply(raw, target, measured)
        self.integral += h * (g.ki * error + g.kt * (u - raw))
        return ControllerOutput(u, (feedforward, proportional, self.integral, derivative))


PID_CONTROLLER = Component(
    "pid", "PID with nominal-model feedforward and anti-windup", PARAMETERS,
    lambda values, context, limiter: PID(settings(PIDGains, "pid", values), context.period,
                                         limiter, context.train),
    (Output("feedforward", "N/kN", "nominal-model feedforward"),
     Output("proportional", "N/kN", "proportional term"),
     Output("integral", "N/kN", "integrator state (after this step)"),
     Output("derivative", "N/kN", "derivative term on the filtered measurement")),
    search_space=(("pid.kp", 1.0, 1000.0), ("pid.ki", 0.0, 500.0), ("pid.kd", 0.0, 500.0),
                  ("pid.tf", 0.01, 2.0), ("pid.kt", 0.0, 20.0), ("pid.feedforward", 0.0, 1.5)),
    state_paths=("integral", "filtered"))
