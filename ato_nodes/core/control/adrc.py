"""Active disturbance rejection controllers (ROS-free).

Han's second-order nonlinear ADRC (seed 000, eq. 6-13; with a bandwidth-
parametrised observer it is seed 003's NLADRC), seed 004's discrete ADRC and a
linear, bandwidth-parametrised ADRC (Gao). Each maps (target speed, measured
speed) to a specific traction/braking force u in N/kN, one call per control
period, through a CommandLimiter.

Discretisation (the papers give continuous-time equations):

* TD: Han's discrete form, v1 += h v2, v2 += h fhan(v1 - r, v2, r0, h0),
  with h the control period.
* ESO: linearly-implicit (backward) Euler with step h. Each fal() term is
  written as g(e) * e with g frozen at the predicted error of the step, and
  the resulting 3x3 linear system is solved in closed form. Backward Euler
  maps every stable pole into the unit disc, so the observer is stable for
  any step, while explicit Euler needs h < ~1/beta1 (0.8 ms for the seed's
  beta1 = 1200) and would force a control period 60x shorter than the
  default 50 ms. The observer is fed the command actually applied, i.e.
  after the saturation of this controller.
* NLSEF: the law u0 = mu1 fal(e1) + mu2 fal(e2) asks the observer's model
  (z1' = z2, z2' = u0) for poles near -mu2 (thousands of rad/s), which no
  sampled loop slower than ~0.3 ms can realise: taken literally it diverges
  at any practical period (measured: also at 1 ms). The default is its
  implicit discretisation: u0 is chosen so that the model's next state
  satisfies the law, with fal gains frozen at the current errors,
      u0 = (k1 (e1 - h z2) + k2 e2) / (1 + h^2 k1 + h k2),  ki = mu_i fal(ei)/ei,
  which tends to the literal law as h -> 0 and is stable for any h
  (`implicit_nlsef = False` gives the literal law).
* b0 is not given by the paper. With an ideal observer the closed loop does
  not depend on it; in the sampled loop b0 = xi / h makes the observer's
  input model match the one-period effect of u on the acceleration, so the
  seed scenarios use xi / 0.05 s = 0.1766.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.errors import ScenarioError
from ..base.kernels import jitable
from ..base.registry import Component, Output
from ..base.spec import param, settings
from ..train.line import Line, neutral_distance
from ..train.plant import TrainParameters
from .estimation import (ESTIMATE_OUTPUTS, EstimatorState, OnBoardEstimator,
                         on_board_actuator, on_board_estimates, on_board_estimator,
                         on_board_scale, on_board_step)
from .limiter import STOPPED, CommandLimiter, LimiterSettings, limit_command, limit_under
from .stepped import STATE_PATHS, ControllerSteps, SteppedController
from .train_model import (Actuator, NominalModel, NominalState, known_resistance,
                          neutral_ceiling, nominal_advance, nominal_predict, nominal_train)


@jitable
def sign(x: float) -> float:
    return (x > 0.0) - (x < 0.0)


@jitable
def fal(e: float, alpha: float, delta: float) -> float:
    """Han's fal(): linear inside |e| <= delta, |e|^alpha outside."""
    if abs(e) <= delta:
        return e / delta ** (1.0 - alpha)
    return sign(e) * abs(e) ** alpha


@jitable
def fal_gain(e: float, alpha: float, delta: float) -> float:
    """fal(e)/e, the local gain of fal (its limit delta^(alpha-1) at e = 0)."""
    a = abs(e)
    if a <= delta:
        return delta ** (alpha - 1.0)
    return a ** (alpha - 1.0)


@jitable
def fhan(x1: float, x2: float, r: float, h0: float) -> float:
    """Han's time-optimal synthesis function (seed 000 eq. 7); sign() is written
    out as comparisons because this runs every step of every candidate."""
    d = r * h0 * h0
    a0 = h0 * x2
    y = x1 + a0
    a1 = math.sqrt(d * (d + 8.0 * abs(y)))
    a2 = a0 + ((y > 0.0) - (y < 0.0)) * (a1 - d) / 2.0
    sy = (((y + d) > 0.0) - ((y + d) < 0.0) - ((y - d) > 0.0) + ((y - d) < 0.0)) / 2.0
    a = (a0 + y - a2) * sy + a2
    sa = (((a + d) > 0.0) - ((a + d) < 0.0) - ((a - d) > 0.0) + ((a - d) < 0.0)) / 2.0
    sign_a = (a > 0.0) - (a < 0.0)
    return -r * (a / d - sign_a) * sa - r * sign_a


@jitable
def td_update(v1: float, v2: float, target: float, r0: float, h0: float, h: float
              ) -> tuple[float, float]:
    """One step of Han's discrete TD."""
    fh = fhan(v1 - target, v2, r0, h0)
    return v1 + h * v2, v2 + h * fh


@jitable
def eso_update(z1: float, z2: float, z3: float, y: float, u: float, beta1: float, beta2: float,
               beta3: float, b0: float, delta: float, h: float) -> tuple[float, float, float]:
    """One linearly-implicit Euler step of the nonlinear ESO (see the module docstring)."""
    predicted = z1 + h * z2 - y
    k1 = h * beta1
    k2 = h * beta2 * fal_gain(predicted, 0.5, delta)
    k3 = h * beta3 * fal_gain(predicted, 0.25, delta)
    # Closed-form solution of (I - hA) z+ = z + h c for the error E = z1+ - y.
    e = (z1 - y + h * z2 + h * h * (z3 + b0 * u)) / (1.0 + k1 + h * k2 + h * h * k3)
    z3 = z3 - k3 * e
    z2 = z2 + h * z3 - k2 * e + h * b0 * u
    return y + e, z2, z3


HAN_ADRC_PARAMETERS = (
    param("adrc.mu1", 6000.0, "NLSEF gain on e1", "controller", 0.0, 1e9),
    param("adrc.mu2", 5500.0, "NLSEF gain on e2", "controller", 0.0, 1e9),
    param("adrc.alpha1", 0.75, "NLSEF exponent on e1", "controller", 0.0, 3.0),
    param("adrc.alpha2", 1.5, "NLSEF exponent on e2", "controller", 0.0, 3.0),
    param("adrc.r0", 5.0, "TD speed factor, m/s^2", "controller", 1e-6, 1e6),
    param("adrc.h0", 0.001, "TD filter factor, s", "controller", 1e-6, 10.0),
    param("adrc.beta1", 1200.0, "ESO gain beta1", "controller", 0.0, 1e9),
    param("adrc.beta2", 1700.0, "ESO gain beta2", "controller", 0.0, 1e9),
    param("adrc.beta3", 4500.0, "ESO gain beta3", "controller", 0.0, 1e9),
    param("adrc.b0", 0.1766, "compensation factor b0 (not in the paper; ~xi / 50 ms, see "
          "docs/internals.md)", "controller", 1e-9, 1e9),
    param("adrc.delta", 0.01, "fal linear-zone half width", "controller", 1e-9, 100.0),
    param("adrc.implicit_nlsef", True, "implicit NLSEF discretisation (false: literal law)",
          "controller"),
)


class HanADRCGains(NamedTuple):
    """Seed 000's parameters (adrc.*; the paper's initial values are the defaults in
    HAN_ADRC_PARAMETERS); b0 and delta are not in the paper."""

    mu1: float
    mu2: float
    alpha1: float
    alpha2: float
    r0: float
    h0: float
    beta1: float
    beta2: float
    beta3: float
    b0: float
    delta: float
    implicit_nlsef: bool


OBSERVER_OUTPUTS = (
    Output("z1", "m/s", "ESO speed estimate"),
    Output("z2", "m/s^2", "ESO acceleration estimate"),
    Output("z3", "m/s^3", "ESO total-disturbance estimate"),
    Output("v1", "m/s", "TD target"),
    Output("v2", "m/s^2", "TD target derivative"),
)


class HanADRCState(NamedTuple):
    """What Han's ADRC carries from one step to the next."""

    z1: float = 0.0         # the nonlinear ESO's (eq. 10) speed (m/s), its derivative,
    z2: float = 0.0         # the total disturbance (eso_update)
    z3: float = 0.0
    v1: float = 0.0         # the tracking differentiator's target (m/s) and derivative
    v2: float = 0.0
    u_applied: float = 0.0  # the command the observer is told: the last one let through


class HanADRCSettings(NamedTuple):
    gains: HanADRCGains
    period: float  # s


def han_adrc(gains: HanADRCGains, period: float, limiter: CommandLimiter) -> SteppedController:
    """Han's second-order nonlinear ADRC: TD + nonlinear ESO + NLSEF (seed 000)."""
    return SteppedController(HAN_ADRC_STEPS, HanADRCSettings(gains, period), limiter)


@jitable
def nlsef(e1: float, e2: float, z2: float, gains: HanADRCGains, h: float) -> float:
    """NLSEF (eq. 12), implicit or literal (see module docstring): u0 from the
    errors e1 = v1 - z1, e2 = v2 - z2."""
    g = gains
    if not g.implicit_nlsef:
        return g.mu1 * fal(e1, g.alpha1, g.delta) + g.mu2 * fal(e2, g.alpha2, g.delta)
    k1 = g.mu1 * fal_gain(e1, g.alpha1, g.delta)
    k2 = g.mu2 * fal_gain(e2, g.alpha2, g.delta)
    return (k1 * (e1 - h * z2) + k2 * e2) / (1.0 + h * h * k1 + h * k2)


@jitable
def han_adrc_start(settings: HanADRCSettings, state: HanADRCState, target: float,
                   measured: float, horizon) -> HanADRCState:
    """The TD starts at the first tracked target, the observer at the first measurement."""
    return HanADRCState(measured, state.z2, state.z3, horizon[-1], state.v2, state.u_applied)


@jitable
def han_adrc_step(settings: HanADRCSettings, state: HanADRCState, target: float,
                  measured: float, horizon, last: float, limits: LimiterSettings):
    """One step of Han's ADRC (ControllerSteps.step), tracking the horizon's end r_k+N;
    outputs z1, z2, z3, v1, v2."""
    g, h, tracked = settings.gains, settings.period, horizon[-1]
    z1, z2, z3 = eso_update(state.z1, state.z2, state.z3, measured, state.u_applied, g.beta1,
                            g.beta2, g.beta3, g.b0, g.delta, h)
    v1, v2 = td_update(state.v1, state.v2, tracked, g.r0, g.h0, h)
    u0 = nlsef(v1 - z1, v2 - z2, z2, g, h)
    u = limit_command((u0 - z3) / g.b0, tracked, measured, last, limits)
    return u, (z1, z2, z3, v1, v2), HanADRCState(z1, z2, z3, v1, v2, u)


HAN_ADRC_STEPS = ControllerSteps(han_adrc_start, han_adrc_step, HanADRCState)


NLADRC_PARAMETERS = (
    param("nladrc.kp", 2.0, "seed 003 NLADRC: proportional gain of the nonlinear PD",
          "controller", 0.0, 1e6),
    param("nladrc.kd", 1.0, "seed 003 NLADRC: derivative gain of the nonlinear PD",
          "controller", 0.0, 1e6),
    param("nladrc.omega", 10.0, "seed 003 NLADRC: observer bandwidth w (b01 = 3w, b02 = 3w^2, "
          "b03 = w^3), rad/s", "controller", 1e-3, 1e4),
    param("nladrc.b", 0.5, "seed 003 NLADRC: compensation factor b", "controller", 1e-9, 1e9),
    param("nladrc.alpha1", 0.75, "seed 003 NLADRC: fal exponent on e1", "controller", 0.0, 3.0),
    param("nladrc.alpha2", 1.25, "seed 003 NLADRC: fal exponent on e2", "controller", 0.0, 3.0),
    param("nladrc.delta", 0.01, "seed 003 NLADRC: fal linear zone", "controller", 1e-9, 100.0),
    param("nladrc.r0", 15.0, "seed 003 NLADRC: TD speed factor r", "controller", 1e-6, 1e6),
    param("nladrc.h0", 0.01, "seed 003 NLADRC: TD filter factor h0, s", "controller",
          1e-6, 10.0),
)


def nladrc_gains(kp: float, kd: float, omega: float, b: float, alpha1: float, alpha2: float,
                 r0: float, h0: float, delta: float) -> HanADRCGains:
    """Seed 003's NLADRC is Han's structure with a bandwidth-parametrised observer
    (b01 = 3w, b02 = 3w^2, b03 = w^3) and the nonlinear PD u0 = kp fal(e1) + kd fal(e2),
    u = (u0 - z3) / b: the same controller with four tuned parameters kp, kd, w, b."""
    return HanADRCGains(mu1=kp, mu2=kd, alpha1=alpha1, alpha2=alpha2, r0=r0, h0=h0,
                        beta1=3.0 * omega, beta2=3.0 * omega ** 2, beta3=omega ** 3, b0=b,
                        delta=delta, implicit_nlsef=True)


DISCRETE_ADRC_PARAMETERS = (
    param("dadrc.b01", 0.9, "seed 004 discrete ESO gain b01 (per step)", "controller", 0.0, 3.0),
    param("dadrc.b02", 0.03, "seed 004 discrete ESO gain b02 (per step)", "controller", 0.0, 3.0),
    param("dadrc.b03", 0.001, "seed 004 discrete ESO gain b03 (per step)", "controller",
          0.0, 3.0),
    param("dadrc.b1", 40.0, "seed 004 NLSEF gain on e1, N/kN per (m/s)^a1", "controller",
          0.0, 1e6),
    param("dadrc.b2", 100.0, "seed 004 NLSEF gain on e2, N/kN per (m/s per step)^a2",
          "controller", 0.0, 1e6),
    param("dadrc.alpha1", 0.75, "seed 004 NLSEF exponent a1 in (0, 1)", "controller", 0.01, 1.0),
    param("dadrc.alpha2", 0.5, "seed 004 NLSEF exponent a2 in (0, 1)", "controller", 0.01, 1.0),
    param("dadrc.b0", 1e-4, "seed 004 input gain b0 per step^2 (xi h^2 / lag)", "controller",
          1e-12, 1e3),
    param("dadrc.delta", 0.01, "seed 004 fal linear zone (below 0.0025 chatters)", "controller",
          1e-6, 10.0),
    param("dadrc.r0", 2.0, "seed 004 TD speed factor, m/s^2", "controller", 1e-6, 1e6),
    param("dadrc.h0", 0.1, "seed 004 TD filter factor, s", "controller", 1e-6, 10.0),
)


class DiscreteADRCGains(NamedTuple):
    """Seed 004's gains (dadrc.*), per step (the control period folded in)."""

    b01: float
    b02: float
    b03: float
    b1: float
    b2: float
    alpha1: float
    alpha2: float
    b0: float
    delta: float
    r0: float
    h0: float


class DiscreteADRCSettings(NamedTuple):
    gains: DiscreteADRCGains
    period: float  # s
    # The observer's fal exponents as printed. Settings, not literals in the step: a
    # literal 0.5 lets the compiler turn |e| ** 0.5 into a square root, whose last bit
    # can differ from the power the Python step computes.
    alpha_z2: float = 0.5
    alpha_z3: float = 0.25


class DiscreteADRCState(NamedTuple):
    z1: float = 0.0         # the observer's speed (m/s), its change per step, and that
    z2: float = 0.0         # change's change per step
    z3: float = 0.0
    v1: float = 0.0         # the tracking differentiator's target (m/s) and derivative
    v2: float = 0.0
    u_applied: float = 0.0  # the command the observer is told: the last one let through


@jitable
def discrete_adrc_start(settings: DiscreteADRCSettings, state: DiscreteADRCState,
                        target: float, measured: float, horizon) -> DiscreteADRCState:
    return DiscreteADRCState(measured, state.z2, state.z3, horizon[-1], state.v2,
                             state.u_applied)


@jitable
def discrete_adrc_step(settings: DiscreteADRCSettings, state: DiscreteADRCState,
                       target: float, measured: float, horizon, last: float,
                       limits: LimiterSettings):
    """Seed 004's discrete second-order ADRC, the ESO exactly as printed:

        e = z1 - y;  z1 += z2 - b01 e;  z2 += z3 - b02 fal(e, 0.5) + b0 u;
        z3 += -b03 fal(e, 0.25);  u = b1 fal(e1, a1) + b2 fal(e2, a2) - z3 / b0

    With the step folded into the gains, z2 is the speed change per step and z3
    its change per step, so the TD's v2 (m/s^2) enters e2 = v2 h - z2 in the same
    per-step unit (the paper leaves this implicit: our reading). The outputs z2
    and z3 are converted back to m/s^2 and m/s^3. It tracks the horizon's end r_k+N."""
    g, h, tracked = settings.gains, settings.period, horizon[-1]
    e = state.z1 - measured
    z1 = state.z1 + state.z2 - g.b01 * e
    z2 = state.z2 + state.z3 - g.b02 * fal(e, settings.alpha_z2, g.delta) \
        + g.b0 * state.u_applied
    z3 = state.z3 - g.b03 * fal(e, settings.alpha_z3, g.delta)
    v1, v2 = td_update(state.v1, state.v2, tracked, g.r0, g.h0, h)
    u0 = g.b1 * fal(v1 - z1, g.alpha1, g.delta) + g.b2 * fal(v2 * h - z2, g.alpha2, g.delta)
    u = limit_command(u0 - z3 / g.b0, tracked, measured, last, limits)
    return u, (z1, z2 / h, z3 / (h * h), v1, v2), DiscreteADRCState(z1, z2, z3, v1, v2, u)


DISCRETE_ADRC_STEPS = ControllerSteps(discrete_adrc_start, discrete_adrc_step,
                                      DiscreteADRCState)


# The linear ADRC's modes as the switches its step reads (LinearADRCGains), each mode
# holding the one before it: ladrc.feedforward as (feedforward, plan_feedforward),
# ladrc.prediction as (delay_aware, predicted_target).
FEEDFORWARD_MODES = {"none": (False, False), "target": (True, False), "plan": (True, True)}
PREDICTION_MODES = {"none": (False, False), "speed": (True, False), "position": (True, True)}
# The switches the modes replaced: (the mode that took its place, its value for true).
RETIRED_SWITCHES = {
    "ladrc.feedforward": ("ladrc.feedforward", "target"),
    "ladrc.plan_feedforward": ("ladrc.feedforward", "plan"),
    "ladrc.delay_aware": ("ladrc.prediction", "speed"),
    "ladrc.predicted_target": ("ladrc.prediction", "position"),
}
PLAN_BAND = param("ladrc.plan_band", 0.5 / 3.6, "linear ADRC with ladrc.feedforward plan: how "
                  "far the speed may be off the target before the command leaves the plan's "
                  "side, m/s", "controller", 0.0, 100.0)


def retired_switch(name: str, value) -> str | None:
    """What a file or --set that gives an old switch of the linear ADRC (`name`: `value`)
    is told: the mode to give instead (one line); None for anything else."""
    if name not in RETIRED_SWITCHES or (name == "ladrc.feedforward" and not (
            isinstance(value, bool) or value in ("true", "false"))):
        return None
    mode, on = RETIRED_SWITCHES[name]
    said = str(value).lower()
    if said == "true":
        return f"{name}: true is an old switch of the linear ADRC: give {mode}: {on}"
    modes = FEEDFORWARD_MODES if mode == "ladrc.feedforward" else PREDICTION_MODES
    return (f"{name}: {said} is an old switch of the linear ADRC: give {mode}: one of "
            f"{', '.join(modes)} ({on} for true; the papers' none is the default)")


def switches_as_modes(values: dict) -> dict:
    """A run's `values` as recorded before the modes (a bag's: the old switches, true or
    false) with the modes they mean in their place; other values as they are."""
    if not isinstance(values.get("ladrc.feedforward"), bool):
        return values
    values = dict(values)
    for mode, (switch, more), modes in (
            ("ladrc.feedforward", ("ladrc.feedforward", "ladrc.plan_feedforward"),
             FEEDFORWARD_MODES),
            ("ladrc.prediction", ("ladrc.delay_aware", "ladrc.predicted_target"),
             PREDICTION_MODES)):
        on = (bool(values.pop(switch, False)), bool(values.pop(more, False)))
        values[mode] = next(name for name, switches in modes.items() if switches == (
            on[0], on[0] and on[1]))
    return values


LINEAR_ADRC_PARAMETERS = (
    param("ladrc.omega_o", 20.0, "linear ADRC observer bandwidth, rad/s", "controller",
          1e-6, 1e6),
    param("ladrc.omega_c", 2.0, "linear ADRC controller bandwidth, rad/s", "controller",
          1e-6, 1e6),
    param("ladrc.b0", 0.0098 / 1.11, "linear ADRC input gain, m/s^2 per N/kN", "controller",
          1e-9, 1e9),
    param("ladrc.feedforward", "none", "linear ADRC's feedforward: none (the papers' "
          "setting); target: the plan's acceleration at the tracked target (needs "
          "controller.preview >= 1) and the nominal train's basic and line resistance (at the "
          "dead-reckoned position) added to the law, the resistance told to the observer, so "
          "it estimates only what the model does not know; plan: with a plan that has forces "
          "(profile.kind strategy), the force the plan holds where the tracked target is in "
          "place of that acceleration, and the command kept on that force's side: no braking "
          "where the plan drives or cruises, no traction where it brakes, none at all where it "
          "coasts, unless the (predicted) speed is more than ladrc.plan_band off the target",
          "controller", choices=tuple(FEEDFORWARD_MODES)),
    param("ladrc.prediction", "none", "linear ADRC's prediction over the actuator's delay: "
          "none (the papers' setting: the observer is fed the command, the law acts on its "
          "speed); speed: the observer is fed the force the nominal actuator applies (dead "
          "time, lag, envelope, neutral sections) and the law acts on the speed predicted "
          "controller.preview steps ahead from the commands already sent (a Smith "
          "predictor); position: as speed, and with a position-indexed plan a train predicted "
          "past where the plan will be controller.preview steps ahead tracks the plan's speed "
          "there (the preview extended on its last slope down), not r_k+N: ahead of its "
          "curve, it brakes for the curve it will meet (the last metres of a stop)",
          "controller", choices=tuple(PREDICTION_MODES)),
    PLAN_BAND,
    param("ladrc.plan_lead", 0.0, "linear ADRC with ladrc.feedforward plan: how early the "
          "command may take the side of the plan's next traction stage, s at the measured "
          "speed: a coasting train more than half ladrc.plan_band behind its target starts "
          "ramping before the stage does, so the ramp and lag do not open a gap (0: at the "
          "stage's start)", "controller", 0.0, 60.0),
    param("ladrc.neutral_cut", False, "linear ADRC: command no traction while the pantograph "
          "(dead-reckoned by the nominal model) is inside a neutral section, nor while it "
          "will be inside one within the nominal dead time and a period at the measured "
          "speed (a command sent then acts only there), traction ramped down before that "
          "at controller.max_rate so the cut is in place as the pantograph enters, "
          "released once it has left; as a real ATO opens the main circuit breaker across "
          "a phase break. The observer and the feedforward are told the cut command",
          "controller"),
    param("ladrc.standstill", False, "linear ADRC: while the train stands (measured speed "
          "below 0.1 m/s) under an input that would slow it down, the brakes react and "
          "nothing is left to estimate: the observer holds its disturbance estimate, "
          "which otherwise winds up over a dwell against the holding brake and keeps the "
          "train braked for seconds after its departure", "controller"),
)


class LinearADRCGains(NamedTuple):
    """Bandwidth parametrisation (ladrc.*): observer bandwidth omega_o, controller omega_c;
    the model-based additions, off in the papers' settings, as switches (linear_adrc_gains()
    reads them from the modes ladrc.feedforward and ladrc.prediction)."""

    omega_o: float
    omega_c: float
    b0: float
    feedforward: bool
    delay_aware: bool
    plan_feedforward: bool
    plan_band: float                # m/s
    plan_lead: float                # s
    neutral_cut: bool
    standstill: bool
    predicted_target: bool


class PlanForces(NamedTuple):
    """A plan's force by position, as the linear ADRC reads it (ladrc.plan_feedforward):
    forces[i] over [positions[i], positions[i + 1]), the last stage's from its start on,
    past the stop too (empty: no plan read)."""

    positions: np.ndarray  # m, increasing
    forces: np.ndarray     # N/kN: + traction or cruise, 0 coasting, - braking


def plan_forces(plan=None) -> PlanForces:
    """The stages of `plan` (a run context's plan with `positions` and `forces`, a
    strategy's: its last row is the stop mark, no stage), or none."""
    if plan is None:
        return PlanForces(np.zeros(0), np.zeros(0))
    return PlanForces(np.asarray(plan.positions[:-1], dtype=float),
                      np.asarray(plan.forces[:-1], dtype=float))


@jitable
def stage_index(plan: PlanForces, position: float) -> int:
    """The stage that holds `position` (the first before the first position)."""
    positions = plan.positions
    low, high = 0, len(positions)
    while high - low > 1:  # positions[low] <= position < positions[high], or low = 0
        middle = (low + high) // 2
        if positions[middle] <= position:
            low = middle
        else:
            high = middle
    return low


@jitable
def planned_force(plan: PlanForces, position: float) -> float:
    """The force the plan holds with the head at `position` (its first stage's before
    the first position), N/kN."""
    return plan.forces[stage_index(plan, position)]


@jitable
def next_force(plan: PlanForces, position: float, reach: float) -> float:
    """The first force other than the one the plan holds at `position` that it holds
    within `reach` m past it, N/kN; that one where it holds no other."""
    stage = stage_index(plan, position)
    held = plan.forces[stage]
    for i in range(stage + 1, len(plan.positions)):
        if plan.positions[i] > position + reach:
            break
        if plan.forces[i] != held:
            return plan.forces[i]
    return held


@jitable
def on_plan_side(u: float, planned: float, coming: float, speed: float, target: float,
                 band: float) -> float:
    """`u` kept on the side of the `planned` force (traction, coasting: none, braking)
    unless `speed` is more than `band` off `target`, then also on the side that closes
    the gap; coasting, also traction where the `coming` force is traction and `speed` is
    more than half `band` below `target` (a lead: the ramp starts before the stage does)."""
    low = -math.inf if planned < 0.0 or speed > target + band else 0.0
    # half the band, not any deficit: at a speed a hair under the target the lead would
    # switch coasting to traction and back on every blip of the law
    high = (math.inf if planned > 0.0 or speed < target - band
            or (planned == 0.0 and coming > 0.0 and speed < target - 0.5 * band) else 0.0)
    return low if u < low else high if u > high else u


@jitable
def coming_force(settings: LinearADRCSettings, nominal: NominalState, there: float,
                 speed: float, held: float) -> float:
    """The force of the plan's next stage past `there` (the tracked target's position)
    if it starts within ladrc.plan_lead seconds at `speed`, N/kN, else `held`, the force
    at `there`; and that one without a lead, or once a neutral section starts within the
    time a command takes to act and fade (dead time, a period, five lag constants): a
    lead's traction has faded before the pantograph enters."""
    lead, model = settings.gains.plan_lead, settings.model
    if lead == 0.0:
        return held
    if model.neutral:
        fade = (len(nominal.pending) + 1) * model.period + 5.0 * model.train.actuator_lag
        if neutral_distance(model.line, nominal.position - model.pantograph_offset) < (
                fade * speed):
            return held
    return next_force(settings.plan, there, lead * speed)


class LinearADRCSettings(NamedTuple):
    gains: LinearADRCGains
    period: float          # s
    l1: float              # the observer's gains, 2 omega_o and omega_o^2
    l2: float
    model: NominalModel    # the nominal train, read with feedforward or delay_aware
    plan: PlanForces       # the plan's forces, read with plan_feedforward
    estimator: OnBoardEstimator  # its resistance scale read with feedforward (settings
                                 # None: off)


class LinearADRCState(NamedTuple):
    z1: float              # the observer's speed, m/s
    z2: float              # the observer's total disturbance, m/s^2
    observer_input: float  # F - w over the last period, N/kN
    u_applied: float       # the last command let through
    model: NominalState
    estimator: EstimatorState | None  # None: off


@jitable
def linear_eso(settings: LinearADRCSettings, state: LinearADRCState,
               measured: float) -> tuple[float, float]:
    """The ESO's z1, z2 after a period (backward Euler in closed form); with standstill
    z2 held while the train stands under an input that would slow it."""
    g, h = settings.gains, settings.period
    if g.standstill and measured < STOPPED and state.z2 + g.b0 * state.observer_input < 0.0:
        return measured, state.z2  # standing, the brakes react: nothing to estimate
    e = (state.z1 - measured + h * (state.z2 + g.b0 * state.observer_input)) / (
        1.0 + h * settings.l1 + h * h * settings.l2)
    return measured + e, state.z2 - h * settings.l2 * e


@jitable
def target_past_preview(horizon, period: float, distance: float) -> float:
    """The tracked target r_k+N (the last entry of `horizon`, the speeds of the coming
    steps along the planned trajectory) for a train predicted to cover `distance` m till
    then: where that is past the preview's end (the train ahead of its plan), the plan
    extended there on the preview's last slope down (not below 0; never up: no speed the
    preview does not show)."""
    last = len(horizon) - 1
    covered = 0.0  # the trapezoid's, as the preview's trajectory is integrated
    for i in range(last):
        covered += 0.5 * period * (horizon[i] + horizon[i + 1])
    final = 0.5 * period * (horizon[last - 1] + horizon[last])
    if distance <= covered or final <= 0.0:
        return horizon[last]
    slope = (horizon[last] - horizon[last - 1]) / final  # per metre
    return min(max(horizon[last] + slope * (distance - covered), 0.0), horizon[last])


@jitable
def linear_adrc_start(settings: LinearADRCSettings, state: LinearADRCState, target: float,
                      measured: float, horizon) -> LinearADRCState:
    return LinearADRCState(measured, state.z2, state.observer_input, state.u_applied,
                           state.model, state.estimator)


@jitable
def law_speed_and_target(settings: LinearADRCSettings, state: LinearADRCState,
                         actuator: Actuator, z1: float, z2: float, horizon, scale: float
                         ) -> tuple[float, float]:
    """The speed the law acts on and the target it tracks: the observer's speed and r_k+N
    (the horizon's end), with delay_aware the speed predicted N = len(horizon) - 1 steps
    ahead by the nominal model with `actuator` (as estimated on board), and with
    predicted_target the plan where the train is then predicted to be."""
    g, ahead, target = settings.gains, len(horizon) - 1, horizon[-1]
    if not (g.delay_aware and ahead):
        return z1, target
    predicted = nominal_predict(settings.model, state.model, z1, z2, g.b0, ahead,
                                state.u_applied, g.feedforward, scale, actuator)
    if g.predicted_target:
        target = target_past_preview(horizon, settings.period, predicted.travelled)
    return predicted.speed, target


@jitable
def linear_adrc_step(settings: LinearADRCSettings, state: LinearADRCState, target: float,
                     measured: float, horizon, last: float, limits: LimiterSettings):
    """First-order linear ADRC for the speed loop (the plant's true relative degree).

    ESO  z1 -> speed, z2 -> total disturbance (acceleration not explained by the input
    b0 (F - w)), gains 2 omega_o and omega_o^2; with r the tracked target r_k+N (the
    horizon's end) and v the speed estimate,
        u = (omega_c (r - v) + a_r - z2) / b0 + w_r.
    In the papers' setting F is the command, w = w_r = a_r = 0 and v = z1. With
    `feedforward`, a_r is the plan's acceleration at r, w the known resistance now
    and w_r at r's planned position (core/control/train_model.py); with `delay_aware`, F
    is the force the nominal actuator applies and v the speed predicted N steps ahead
    (the commands inside the dead time and lag act first): the error its command can
    still change; the known basic resistance and the nominal actuator's envelope are
    scaled by the on-board estimates (1 off); with `standstill` the ESO holds z2 while
    the train stands under an input that would slow it (the brakes' reaction is no
    disturbance); with `predicted_target` r is the plan where the train is predicted to
    be (a train ahead of its plan). The ESO is integrated by backward Euler in closed
    form, stable for any step. Outputs z1, z2 and the estimates (ESTIMATE_OUTPUTS)."""
    g, h, model, ahead = settings.gains, settings.period, settings.model, len(horizon) - 1
    actuator = on_board_actuator(settings.estimator, state.estimator, model)
    scale = on_board_scale(state.estimator)
    z1, z2 = linear_eso(settings, state, measured)
    speed, target = law_speed_and_target(settings, state, actuator, z1, z2, horizon, scale)
    law = (g.omega_c * (target - speed) - z2) / g.b0
    resistance = 0.0  # known to the observer over the coming period
    if g.feedforward:
        travelled = 0.0  # sum(horizon[:-1]), left to right
        for i in range(ahead):
            travelled += horizon[i]
        there = state.model.position + h * travelled  # where the tracked target is planned
        if g.plan_feedforward:
            force = planned_force(settings.plan, there)
            coming = coming_force(settings, state.model, there, measured, force)
            law = on_plan_side(law + force, force, coming, speed, target, g.plan_band)
        else:
            planned = (horizon[ahead] - horizon[ahead - 1]) / h if ahead else 0.0
            law += planned / g.b0 + known_resistance(model, target, there, scale)
        resistance = known_resistance(model, measured, state.model.position, scale)
    ceiling = (neutral_ceiling(model, state.model, measured, limits.max_change)
               if g.neutral_cut else math.inf)  # the observer is told the cut command
    u = limit_under(law, ceiling, target, measured, last, limits)
    force, nominal = u, state.model
    if g.feedforward or g.delay_aware or g.neutral_cut:  # the model dead-reckons the position
        force, nominal = nominal_advance(model, state.model, u, measured, actuator)
    observer_input = (force if g.delay_aware else u) - resistance
    estimator = on_board_step(settings.estimator, state.estimator, u, measured)
    return u, (z1, z2) + on_board_estimates(settings.estimator, estimator), LinearADRCState(
        z1, z2, observer_input, u, nominal, estimator)


LINEAR_ADRC_STEPS = ControllerSteps(linear_adrc_start, linear_adrc_step, LinearADRCState)


def linear_adrc_of(gains: LinearADRCGains, period: float, limiter: CommandLimiter,
                   train: TrainParameters,
                   estimator: tuple[OnBoardEstimator, EstimatorState | None],
                   position: float = 0.0, line: Line | None = None,
                   plan: PlanForces | None = None) -> SteppedController:
    """The linear ADRC with the nominal model of `train` on `line` from `position`, the
    on-board `estimator` (on_board_estimator's settings and state) and the plan's
    forces, with plan_feedforward."""
    return _linear_adrc(gains, limiter, nominal_train(train, period, position, line),
                        estimator, plan)


def _linear_adrc(gains: LinearADRCGains, limiter: CommandLimiter,
                 nominal: tuple[NominalModel, NominalState],
                 estimator: tuple[OnBoardEstimator, EstimatorState | None],
                 plan: PlanForces | None) -> SteppedController:
    (model, start), (on_board, estimated) = nominal, estimator
    return SteppedController(LINEAR_ADRC_STEPS, LinearADRCSettings(
        gains, model.period, 2.0 * gains.omega_o, gains.omega_o ** 2, model,
        plan if plan is not None else plan_forces(), on_board), limiter,
        LinearADRCState(0.0, 0.0, 0.0, 0.0, start, estimated))


def _switches(values, name: str, modes: dict[str, tuple[bool, bool]]) -> tuple[bool, bool]:
    """The switches of the mode `values` give `name` (a run's values built by hand, not
    through the schema's check, may hold anything: one line then)."""
    mode = values[name]
    if mode not in modes:
        raise ScenarioError(retired_switch(name, mode) or f"{name} must be one of "
                            f"{', '.join(modes)}; got {mode!r}")
    return modes[mode]


def linear_adrc_gains(values) -> LinearADRCGains:
    """The linear ADRC's gains and switches from its parameters (ladrc.*, the modes
    ladrc.feedforward and ladrc.prediction as their switches); ScenarioError (one line)
    for a plan setting without the plan's feedforward, which would change nothing."""
    feedforward, plan_feedforward = _switches(values, "ladrc.feedforward", FEEDFORWARD_MODES)
    delay_aware, predicted_target = _switches(values, "ladrc.prediction", PREDICTION_MODES)
    if not plan_feedforward:
        for name, off in (("ladrc.plan_band", PLAN_BAND.default), ("ladrc.plan_lead", 0.0)):
            if values[name] != off:
                raise ScenarioError(f"{name} applies to ladrc.feedforward plan, not "
                                    f"{values['ladrc.feedforward']}")
    return LinearADRCGains(
        values["ladrc.omega_o"], values["ladrc.omega_c"], values["ladrc.b0"], feedforward,
        delay_aware, plan_feedforward, values["ladrc.plan_band"], values["ladrc.plan_lead"],
        values["ladrc.neutral_cut"], values["ladrc.standstill"], predicted_target)


def linear_adrc(values, context, limiter: CommandLimiter) -> SteppedController:
    gains = linear_adrc_gains(values)
    plan = plan_forces()
    if gains.plan_feedforward:
        if not hasattr(context.plan, "forces"):
            raise ScenarioError("ladrc.feedforward plan needs a plan with forces (profile.kind "
                                f"strategy), not profile.kind {values['profile.kind']}")
        plan = plan_forces(context.plan)
    if gains.predicted_target and not context.plan.position_indexed:
        raise ScenarioError("ladrc.prediction position needs a position-indexed plan, not "
                            f"profile.kind {values['profile.kind']}")
    nominal = nominal_train(context.train, context.period, values["plant.initial_position"],
                            context.line)  # the estimator's model shares its line tables
    return _linear_adrc(gains, limiter, nominal, on_board_estimator(
        values, context.period, context.line, nominal[0]), plan)


HAN_ADRC = Component(
    "han_adrc", "seed 000: Han's nonlinear ADRC", HAN_ADRC_PARAMETERS,
    lambda values, context, limiter: han_adrc(settings(HanADRCGains, "adrc", values),
                                              context.period, limiter),
    OBSERVER_OUTPUTS, observer_gain=lambda values: values["adrc.b0"], steps=HAN_ADRC_STEPS,
    search_space=(("adrc.mu1", 600.0, 60000.0), ("adrc.mu2", 550.0, 55000.0),
                  ("adrc.beta1", 120.0, 12000.0), ("adrc.beta2", 170.0, 17000.0),
                  ("adrc.beta3", 450.0, 45000.0)),
    state_paths=STATE_PATHS)

NLADRC = Component(
    "nladrc", "seed 003: NLADRC, bandwidth-parametrised observer", NLADRC_PARAMETERS,
    lambda values, context, limiter: han_adrc(nladrc_gains(**{
        spec.name.split(".", 1)[1]: values[spec.name] for spec in NLADRC_PARAMETERS}),
        context.period, limiter),
    OBSERVER_OUTPUTS, observer_gain=lambda values: values["nladrc.b"], steps=HAN_ADRC_STEPS,
    search_space=(("nladrc.kp", 0.05, 20.0), ("nladrc.kd", 0.05, 20.0),
                  ("nladrc.omega", 0.5, 40.0), ("nladrc.b", 0.002, 0.5)),
    state_paths=STATE_PATHS)

DISCRETE_ADRC = Component(
    "discrete_adrc", "seed 004: discrete ADRC", DISCRETE_ADRC_PARAMETERS,
    lambda values, context, limiter: SteppedController(DISCRETE_ADRC_STEPS, DiscreteADRCSettings(
        settings(DiscreteADRCGains, "dadrc", values), context.period), limiter),
    OBSERVER_OUTPUTS,
    observer_gain=lambda values: values["dadrc.b0"] / values["run.period"] ** 2,  # per step^2
    search_space=(("dadrc.b01", 0.1, 2.5), ("dadrc.b02", 0.001, 1.0),
                  ("dadrc.b03", 0.00001, 0.1), ("dadrc.b1", 1.0, 300.0), ("dadrc.b2", 1.0, 1000.0)),
    state_paths=STATE_PATHS, steps=DISCRETE_ADRC_STEPS)

LINEAR_ADRC = Component(
    "linear_adrc", "first-order linear ADRC", LINEAR_ADRC_PARAMETERS,
    linear_adrc,
    (Output("z1", "m/s", "ESO speed estimate"),
     Output("z2", "m/s^2", "ESO total-disturbance estimate"), *ESTIMATE_OUTPUTS),
    search_space=(("ladrc.omega_o", 2.0, 40.0), ("ladrc.omega_c", 0.3, 6.0),
                  ("ladrc.b0", 0.006, 0.013)),
    state_paths=STATE_PATHS, steps=LINEAR_ADRC_STEPS, estimates=True)
