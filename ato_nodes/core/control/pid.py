"""PID speed controller: the industrial baseline every comparison needs (ROS-free).

    u = ff + kp e + I + D,   e = r - y   (N/kN; r the tracked target, y the measured speed)

* feedforward, weighted by `feedforward` (0 off, 1 full): the command the nominal
  train (the run context's model) needs to follow the plan, a_r / xi + w0(r), with
  a_r the planned acceleration at the tracked target from the preview horizon,
  (r_k+N - r_k+N-1) / h (0 without preview), w0 scaled by the on-board estimate of
  the resistance (core/control/estimation.py; 1 with the estimator off);
* derivative on the measurement, not on the error (a target step gives no kick),
  through a first-order filter of time constant `tf` (backward Euler);
* integral with back-calculation anti-windup: while the limiter cuts the command,
  the integrator is driven back at rate `kt` (1/s) times the cut, so it does not
  wind up at saturation, a jerk limit or a neutral section.
"""

from __future__ import annotations

from typing import NamedTuple

from ..base.kernels import jitable
from ..base.registry import Component, Output
from ..base.spec import param, settings
from ..train.plant import TrainConstants, basic_resistance
from .estimation import (ESTIMATE_OUTPUTS, EstimatorState, OnBoardEstimator,
                         on_board_estimates, on_board_estimator, on_board_scale, on_board_step)
from .limiter import LimiterSettings, limit_command
from .stepped import STATE_PATHS, ControllerSteps, SteppedController

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


class PIDGains(NamedTuple):
    kp: float
    ki: float
    kd: float
    tf: float
    kt: float
    feedforward: float


class PIDSettings(NamedTuple):
    gains: PIDGains
    period: float  # s
    train: TrainConstants  # the nominal train (the feedforward's model)
    estimator: OnBoardEstimator  # settings None: off


class PIDState(NamedTuple):
    integral: float  # N/kN
    filtered: float  # m/s, the measurement through the derivative's filter
    estimator: EstimatorState | None  # None: off


@jitable
def pid_start(settings: PIDSettings, state: PIDState, target: float, measured: float,
              horizon) -> PIDState:
    return PIDState(state.integral, measured, state.estimator)


@jitable
def pid_step(settings: PIDSettings, state: PIDState, target: float, measured: float, horizon,
             last: float, limits: LimiterSettings):
    """One step (ControllerSteps.step), tracking the horizon's end r_k+N; outputs
    feedforward, proportional, integral (after the step), derivative and the estimates
    (ESTIMATE_OUTPUTS)."""
    g, h, train, tracked = settings.gains, settings.period, settings.train, horizon[-1]
    planned_acceleration = (horizon[-1] - horizon[-2]) / h if len(horizon) > 1 else 0.0
    feedforward = g.feedforward * (
        planned_acceleration / train.xi + on_board_scale(state.estimator) * basic_resistance(
            tracked, train.davis_a, train.davis_b, train.davis_c))
    previous = state.filtered
    filtered = previous + h / (g.tf + h) * (measured - previous)
    derivative = -g.kd * (filtered - previous) / h
    error = tracked - measured
    proportional = g.kp * error
    raw = feedforward + proportional + state.integral + derivative
    u = limit_command(raw, tracked, measured, last, limits)
    integral = state.integral + h * (g.ki * error + g.kt * (u - raw))
    estimator = on_board_step(settings.estimator, state.estimator, u, measured)
    return u, (feedforward, proportional, integral, derivative) + on_board_estimates(
        settings.estimator, estimator), PIDState(integral, filtered, estimator)


PID_STEPS = ControllerSteps(pid_start, pid_step, PIDState)


def _pid(values, context, limiter) -> SteppedController:
    on_board, estimated = on_board_estimator(values, context.period, context.line)
    return SteppedController(PID_STEPS, PIDSettings(
        settings(PIDGains, "pid", values), context.period, context.train.constants(),
        on_board), limiter, PIDState(0.0, 0.0, estimated))


PID_CONTROLLER = Component(
    "pid", "PID with nominal-model feedforward and anti-windup", PARAMETERS, _pid,
    (Output("feedforward", "N/kN", "nominal-model feedforward"),
     Output("proportional", "N/kN", "proportional term"),
     Output("integral", "N/kN", "integrator state (after this step)"),
     Output("derivative", "N/kN", "derivative term on the filtered measurement"),
     *ESTIMATE_OUTPUTS),
    search_space=(("pid.kp", 1.0, 1000.0), ("pid.ki", 0.0, 500.0), ("pid.kd", 0.0, 500.0),
                  ("pid.tf", 0.01, 2.0), ("pid.kt", 0.0, 20.0), ("pid.feedforward", 0.0, 1.5)),
    state_paths=STATE_PATHS, steps=PID_STEPS, estimates=True)
