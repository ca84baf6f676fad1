"""The sliding-mode speed control law, as pure functions of NamedTuples (no ROS, no
registry): the `smc` kind's ControllerSteps, which ato_nodes runs in Python and compiled,
and which a node of its own may call as they are.

    e = r - y,  s = e + lambda * I,  I = integral of e dt
    u = ff + lambda * e / xi + k * sat(s / phi)

r the tracked target (r_k+N, the horizon's last: r_k without preview), y the measured
speed, xi the nominal train's m/s^2 per N/kN. With dv/dt = xi (u - w0(v)) + d and
ff = a_r / xi + w0(r) (the nominal-model feedforward the PID uses: the planned
acceleration a_r from the horizon and the Davis resistance w0 at r), the equivalent
term lambda * e / xi makes ds/dt = -xi * k * sat(s / phi) - d: s is driven into the
boundary layer |s| < phi, where the saturation is linear (no chattering), and held
there against a disturbance up to xi * k. The integral grows only inside the boundary
layer and while the limiter lets the command through (conditional integration: no
wind-up while s is being reached, at saturation or at a jerk limit).
"""

from __future__ import annotations

from typing import NamedTuple

from ato_nodes.plugin import (CONTROLLER_NODES, ControllerSteps, LimiterSettings,
                              TrainConstants, basic_resistance, jitable, limit_command, param,
                              settings)

PARAMETERS = (
    param("smc.integral_weight", 0.5, "lambda: weight of the error's integral in the sliding "
          "surface s = e + lambda * integral(e), and of the equivalent term lambda e / xi, 1/s",
          CONTROLLER_NODES, 0.0, 100.0),
    param("smc.gain", 100.0, "k: switching gain, the command that drives s into the boundary "
          "layer (holds against disturbances up to xi k), N/kN", CONTROLLER_NODES, 0.0, 1e6),
    param("smc.boundary", 1.0, "phi: boundary layer of the saturation sat(s / phi), m/s",
          CONTROLLER_NODES, 1e-6, 100.0),
    param("smc.feedforward", 1.0, "weight of the nominal-model feedforward (planned "
          "acceleration and basic resistance), 0 = off", CONTROLLER_NODES, 0.0, 2.0),
)


class SMCGains(NamedTuple):
    integral_weight: float  # 1/s
    gain: float             # N/kN
    boundary: float         # m/s
    feedforward: float      # weight


class SMCSettings(NamedTuple):
    gains: SMCGains
    period: float           # s
    train: TrainConstants   # the nominal train (the feedforward's and xi's model)


class SMCState(NamedTuple):
    integral: float         # m: the integral of the tracking error


def smc_settings(values, period: float, train: TrainConstants) -> SMCSettings:
    """The law's settings from a mapping of the smc.* parameters' values (a run's, or
    {spec.name: spec.default for spec in PARAMETERS}), the control period (s) and the
    nominal train's constants."""
    return SMCSettings(settings(SMCGains, "smc", values), float(period), train)


@jitable
def smc_start(settings: SMCSettings, state: SMCState, target: float, measured: float,
              horizon) -> SMCState:
    return SMCState(0.0)


@jitable
def smc_step(settings: SMCSettings, state: SMCState, target: float, measured: float, horizon,
             last: float, limits: LimiterSettings):
    """One step: (u, (sliding_surface, feedforward, equivalent, switching), state)."""
    g, h, train = settings.gains, settings.period, settings.train
    tracked = horizon[-1]
    planned_acceleration = (horizon[-1] - horizon[-2]) / h if len(horizon) > 1 else 0.0
    feedforward = g.feedforward * (planned_acceleration / train.xi + basic_resistance(
        tracked, train.davis_a, train.davis_b, train.davis_c))
    error = tracked - measured
    surface = error + g.integral_weight * state.integral
    ratio = surface / g.boundary
    switching = g.gain * (ratio if -1.0 < ratio < 1.0 else (1.0 if ratio > 0.0 else -1.0))
    equivalent = g.integral_weight * error / train.xi
    raw = feedforward + equivalent + switching
    u = limit_command(raw, tracked, measured, last, limits)
    inside = -1.0 < ratio < 1.0
    integral = state.integral + h * error if inside and u == raw else state.integral
    return u, (surface, feedforward, equivalent, switching), SMCState(integral)


SMC_STEPS = ControllerSteps(smc_start, smc_step, SMCState)
