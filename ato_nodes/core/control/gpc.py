"""Generalized predictive control on a learned or a mechanistic train model (seed 001),
ROS-free.

Every step k (y(k) the measured speed, m/s; u the command, N/kN):

1. Linearise the prediction model at the current regressor into an ARX model
       y(k+1) = c + sum_j a_j y(k+1-j) + sum_j b_j u(k+1-nk-j)
   (the LSSVM through its analytic RBF gradient, the paper's Taylor expansion; the
   mechanistic model from the nominal train's equations; the multi-model by blending
   its ARX models by the current speed). The constant c carries the filtered one-step
   residual of the last prediction (`gpc.bias_filter`), so a model error that
   persists (a heavier train) is fed back and tracking is offset-free.
2. Predict over P steps: the free response (commands held at u(k-1)) and the step
   responses of the Nu future command moves du(k) .. du(k+Nu-1) (u held after Nu).
3. Minimise sum_j q (y(k+j) - r(k+j))^2 + r sum_i du(k+i)^2, r(k+j) the planned target
   from the run context's preview (controller.preview >= P). Constrained (the
   default): a QP with |du| <= the jerk limit (controller.max_rate h) and the
   command inside [controller.u_min, controller.u_max] and the train's traction and
   brake envelope at the current speed, solved by DAQP (a dual active-set solver
   for small dense QPs: ~10 us at Nu = 5 here, against ~160 us for OSQP and ~100 ms
   of modelling per call for cvxpy). Unconstrained: the paper's closed form, then
   the limiter clips.
4. u(k) = u(k-1) + du(k), through the shared CommandLimiter.

The models see the effective command: the command clipped to the nominal train's
envelope at the measured speed (core/control/identification.py: why).

With the on-board estimator (estimator.enabled, core/control/estimation.py), the
constraints take the estimated envelope (the nominal over the estimated mass), and
the ARX constant the acceleration the estimated resistance adds to the nominal's,
d = -xi (r - 1) w0(y(k)): a constant acceleration d ramps y by h d a step when
c grows by h d sum_j j a_j (the models' a sum to ~1), whatever the model.

Online correction (LSSVM, `gpc.correction`): after y(k) arrives, a sample whose
one-step prediction error exceeds `gpc.correction_threshold` (the paper's 2 km/h)
joins the model (core/control/lssvm.py: factor update, bounded window); deterministic, so a
node and simulate() stay bit-identical.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import daqp
import numpy as np

from ..base.errors import ScenarioError
from ..base.kernels import compiled
from ..base.registry import Component, Controller, ControllerOutput, Output
from ..base.spec import param
from ..base.units import KMH
from ..train.plant import force_limits
from .estimation import (ESTIMATE_OUTPUTS, OnBoardEstimator, estimated_force_limits,
                         on_board_estimates, on_board_estimator, on_board_step)
from .limiter import CommandLimiter, holds
from .lssvm import load_model

PREDICTIONS = ("lssvm", "mechanistic", "multimodel")

PARAMETERS = (
    param("gpc.prediction", "lssvm", "GPC prediction model: lssvm (the learned model of "
          "gpc.model), mechanistic (the nominal train's own equations) or multimodel (the "
          "linear ARX models of gpc.model, blended by speed)", "controller",
          choices=PREDICTIONS),
    param("gpc.model", "", "model file (.npz, scripts/identify.py); relative to the scenario "
          "file, else to msg_config/", "controller"),
    param("gpc.horizon", 20, "prediction horizon P, steps (controller.preview must be >= P)",
          "controller", 1, 200),
    param("gpc.control_horizon", 3, "control horizon Nu, steps", "controller", 1, 20),
    param("gpc.q", 1.0, "weight of the squared speed error, per (m/s)^2", "controller",
          0.0, 1e9),
    param("gpc.r", 1e-3, "weight of the squared command move, per (N/kN)^2", "controller",
          1e-12, 1e9),
    param("gpc.constrained", True, "solve the input constraints as a QP (DAQP); false = the "
          "paper's unconstrained closed form, clipped by the limiter", "controller"),
    param("gpc.bias_filter", 3.0, "time constant of the filter on the one-step residual fed "
          "back into the prediction, s (0 = no feedback)", "controller", 0.0, 1e4),
    param("gpc.correction", True, "online correction of the LSSVM model during the run",
          "controller"),
    param("gpc.correction_threshold", 2.0 * KMH, "one-step prediction error beyond which a "
          "sample joins the model, m/s (the paper's 2 km/h)", "controller", 0.0, 100.0),
    param("gpc.window", 500, "corrections the model keeps beyond its identification samples "
          "(the oldest leaves first)", "controller", 0, 100000),
    param("gpc.berthing_speed", 0.0, "berthing mode: the cost counts the predicted speeds up "
          "to the first planned target at or below this speed (the stop; at least the model's "
          "input delay + 1 steps), m/s; beyond the stop the linear model rolls the train on "
          "backwards under the brake, and the whole horizon (0, the paper's) eases the "
          "braking into the mark", "controller", 0.0, 10.0),
    param("gpc.hold", False, "while the limiter holds the train at its berth "
          "(controller.holding_brake, the target at most controller.holding_target, the train "
          "stopped), the fed-back residual and the online correction do not learn from it: "
          "standstill under the brake is not a model error", "controller"),
)


@dataclass(frozen=True)
class Arx:
    """y(k+1) = c + sum_j a[j-1] y(k+1-j) + sum_j b[j-1] u(k+1-delay-j)."""

    c: float
    a: np.ndarray  # float64, a_1 .. a_na
    b: np.ndarray  # float64, b_1 .. b_nb
    delay: int

    def predict(self, speeds, commands) -> float:
        """One step from histories ending with y(k) and u(k)."""
        value = self.c
        for j, a in enumerate(self.a, 1):
            value += a * speeds[-j]
        for j, b in enumerate(self.b, 1):
            value += b * commands[-self.delay - j]
        return value


class LearnedModel:
    """The LSSVM of a model file, linearised by its analytic gradient."""

    def __init__(self, model, correct: bool, threshold: float):
        self.model, self.layout = model, model.layout
        self.correct, self.threshold = correct, threshold
        self.delay = self.layout.delay
        self.history = max(self.layout.speed_lags, self.layout.history + 1)
        # x(k+1) from the histories (speeds end with y(k), commands with u(k-1)), u(k),
        # not chosen yet, taken as u(k-1): the positions from the end it reads
        self.speed_positions = -np.arange(1, self.layout.speed_lags + 1)
        self.command_positions = -np.maximum(self.delay + np.arange(self.layout.command_lags), 1)

    def linearise(self, speeds, commands) -> Arx:
        x = np.concatenate((speeds[self.speed_positions], commands[self.command_positions]))
        value, gradient = self.model.linearise(x)
        na = self.layout.speed_lags
        a = gradient[:na].copy()
        a[0] += 1.0  # the model learns the increment y(k+1) - y(k)
        return Arx(value - float(gradient @ x), a, gradient[na:], self.delay)

    def observe(self, speeds, commands, error: float) -> bool:
        """y(k) has arrived (speeds end with it, commands with u(k-1)) with the one-step
        error of the model's last (linearised) prediction: beyond the threshold, the
        sample joins the model."""
        if not self.correct or abs(error) <= self.threshold:
            return False
        return self.model.add(self.layout.regressor(speeds[:-1], commands),
                              speeds[-1] - speeds[-2])


class MultiModel:
    """Linear ARX models around operating speeds, blended by Gaussian weights of y(k)."""

    def __init__(self, layout, centres, width: float, coefficients):
        self.layout, self.centres, self.width = layout, centres, width
        self.coefficients = coefficients
        self.delay = layout.delay
        self.history = max(layout.speed_lags, layout.history + 1)

    def row(self, speed: float) -> np.ndarray:
        """The blended coefficients [c, a.., b..] at this speed."""
        weights = np.exp(-0.5 * ((speed - self.centres) / self.width) ** 2)
        if not weights.sum() > 0.0:  # far outside every centre: the nearest alone
            weights = (np.abs(speed - self.centres)
                       == np.abs(speed - self.centres).min()).astype(float)
        return weights @ self.coefficients / weights.sum()

    def linearise(self, speeds, commands) -> Arx:
        row = self.row(speeds[-1])
        na = self.layout.speed_lags
        return Arx(float(row[0]), row[1:1 + na], row[1 + na:], self.layout.delay)

    def observe(self, speeds, commands, error: float) -> bool:
        return False


class MechanisticModel:
    """The nominal train's equations (the run context's train), discretised exactly for
    a command held over the period (zero-order hold) through the first-order lag tau,
    the dead time as an input delay, the resistance linearised at y(k) and held over
    the period. With e = exp(-h/tau), c1 = tau (1 - e) / h, G = h xi and u_d(k) the
    command acting over [k, k+1] (u(k - dead)):
        F(k+1) = e F(k) + (1 - e) u_d(k)
        y(k+1) = y(k) + G (c1 F(k) + (1 - c1) u_d(k) - w0(y(k)))
    and, F eliminated,
        y(k+1) = (1 + e) y(k) - e y(k-1) + G ((1 - c1) u_d(k) + (c1 - e) u_d(k-1)
                 - w0(y(k)) + e w0(y(k-1)))."""

    def __init__(self, train, period: float):
        self.train, self.h = train, period
        self.dead = round(train.dead_time / period)
        tau = train.actuator_lag
        self.lag = math.exp(-period / tau) if tau > 0 else 0.0
        self.c1 = tau * (1.0 - self.lag) / period if tau > 0 else 0.0
        self.delay = self.dead
        self.history = self.dead + 3

    def linearise(self, speeds, commands) -> Arx:
        train, h, e, c1 = self.train, self.h, self.lag, self.c1
        v = speeds[-1]
        gain = h * train.xi
        slope = train.davis_b + 2.0 * train.davis_c * abs(v)  # dw0/dv, N/kN per m/s
        w0 = train.resistance(v) - slope * v  # w0(y) ~ w0 + slope y near v
        if e == 0.0:
            return Arx(-gain * w0, np.array((1.0 - gain * slope,)), np.array((gain,)), self.dead)
        return Arx(-gain * w0 * (1.0 - e),
                   np.array((1.0 + e - gain * slope, -e + e * gain * slope)),
                   np.array((gain * (1.0 - c1), gain * (c1 - e))), self.dead)

    def observe(self, speeds, commands, error: float) -> bool:
        return False


@dataclass(frozen=True)
class GPCSettings:
    horizon: int
    control_horizon: int
    q: float
    r: float
    constrained: bool
    bias_filter: float
    berthing_speed: float  # m/s, 0: the whole horizon (the paper's)
    hold: bool             # no learning while the limiter holds the train


def _free_and_forced(c: float, a: np.ndarray, b: np.ndarray, delay: int, speeds: np.ndarray,
                     commands: np.ndarray, horizon: int, moves: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(free response y(k+1..k+P) with u held at u(k-1), step-response matrix
    G: P x Nu, G[j, i] the response at k+j+1 to a unit move at k+i, held) of the ARX
    model from the histories (speeds end with y(k), commands with u(k-1)). Plain
    loops, P (na + nb) products: compiled below when numba is installed."""
    na, nb, last = len(a), len(b), len(commands) - 1
    trajectory = np.empty(na + horizon)  # y(k+1-na) .. y(k+P)
    trajectory[:na] = speeds[len(speeds) - na:]
    free, step = np.empty(horizon), np.empty(horizon)
    for j in range(1, horizon + 1):
        value, response = c, 0.0
        for i in range(1, na + 1):
            value += a[i - 1] * trajectory[na + j - 1 - i]
            if j > i:
                response += a[i - 1] * step[j - i - 1]
        for i in range(1, nb + 1):
            m = j - delay - i  # u(k+m): the held u(k-1) from m = -1 on
            value += b[i - 1] * commands[last + 1 + m if m < -1 else last]
            if m >= 0:
                response += b[i - 1]
        trajectory[na + j - 1] = value
        free[j - 1], step[j - 1] = value, response
    matrix = np.zeros((horizon, moves))
    for j in range(horizon):
        for i in range(min(j + 1, moves)):
            matrix[j, i] = step[j - i]
    return free, matrix


# the same operations in the same order (numba keeps IEEE semantics): the same bits
free_and_forced = compiled(_free_and_forced) or _free_and_forced


def _push(history: np.ndarray, value: float) -> None:
    """Drop the oldest entry, append the newest."""
    history[:-1] = history[1:]
    history[-1] = value


class GPC(Controller):
    def __init__(self, settings: GPCSettings, model, period: float, limiter: CommandLimiter,
                 train, envelope: bool, estimator: tuple):
        """`estimator`: on_board_estimator's settings and departure state."""
        if settings.horizon <= model.delay:
            raise ScenarioError(f"gpc.horizon = {settings.horizon} does not reach past the "
                                f"model's input delay of {model.delay} steps")
        self.s, self.model, self.limiter = settings, model, limiter
        self.train, self.period = train, period
        # the nominal train's traction and brake envelope (None: no envelope)
        self.envelope = train.envelope if envelope else None
        self.estimator: OnBoardEstimator = estimator[0]
        self.estimated = estimator[1]  # None: off
        self.nu = min(settings.control_horizon, settings.horizon)
        self.bias_gain = period / (settings.bias_filter + period) if settings.bias_filter else 0.0
        self.speeds = np.zeros(0)
        self.commands = np.zeros(0)
        self.expected: float | None = None  # the model's prediction of the next y(k)
        self.bias = 0.0
        self.added = 0
        self.lags = np.zeros(0)  # 1 .. na, the weights of sum_j j a_j
        moves = np.arange(self.nu)
        self.cumulative = (moves[:, None] >= moves[None, :]).astype(float)  # u = u0 + C du
        self.move_weight = settings.r * np.eye(self.nu)
        rate = limiter.max_change if limiter.max_change > 0 else math.inf
        self.move_limit = np.full(self.nu, min(rate, 1e30))  # |du| per step
        self.reach = rate * np.arange(1, self.nu + 1)  # what the jerk limit can reach

    def start(self, target: float, measured: float) -> None:
        size = self.model.history + 1
        self.speeds = np.full(size, float(measured))
        self.commands = np.zeros(size)

    def _responses(self, arx: Arx, bias: float) -> tuple[np.ndarray, np.ndarray]:
        """(free response, step-response matrix) of `arx`, its constant plus `bias`, from
        the histories."""
        return free_and_forced(arx.c + bias, arx.a, arx.b, arx.delay, self.speeds,
                               self.commands, self.s.horizon, self.nu)

    def force_range(self, speed: float) -> tuple[float, float]:
        """(brake, traction) the train can apply at this speed, N/kN: the nominal's, or
        as estimated on board (unbounded without an envelope)."""
        if self.envelope is None:
            return -math.inf, math.inf
        if self.estimated is not None:
            return estimated_force_limits(self.estimator.settings, self.estimated, speed)
        return force_limits(speed, self.envelope)

    def estimated_resistance_change(self, arx: Arx) -> float:
        """What the ARX constant gains from the estimated resistance (module docstring)."""
        train, speed = self.train, self.speeds[-1]
        if len(self.lags) != len(arx.a):  # once: every ARX of the model has its na
            self.lags = np.arange(1, len(arx.a) + 1)
        acceleration = -train.xi * (self.estimated.resistance_scale - 1.0) * train.resistance(
            speed)
        return self.period * acceleration * float(self.lags @ arx.a)

    def step(self, target: float, measured: float, horizon) -> ControllerOutput:
        s = self.s
        if len(horizon) < s.horizon + 1:
            raise ValueError("the GPC needs controller.preview >= gpc.horizon")
        _push(self.speeds, measured)
        error = self._learn(target, measured)
        model_arx = self.model.linearise(self.speeds, self.commands)
        if self.estimated is not None:  # the model's own prediction and error include it
            model_arx = dataclasses.replace(
                model_arx, c=model_arx.c + self.estimated_resistance_change(model_arx))
        free, matrix = self._responses(model_arx, self.bias)
        reference = np.asarray(horizon[1:s.horizon + 1], dtype=float)
        if s.berthing_speed > 0.0:
            free, matrix, reference = self._berthing(free, matrix, reference)
        weighted = s.q * matrix.T
        hessian = weighted @ matrix + self.move_weight
        gradient = weighted @ (free - reference)
        previous = self.limiter.last
        brake, traction = self.force_range(measured)
        move = self._solve(hessian, gradient, previous, max(self.limiter.u_min, brake),
                           min(self.limiter.u_max, traction))
        u = self.limiter.apply(previous + move, target, measured)
        # what the models see: the part of the command the train can apply (the nominal
        # envelope), as in identification
        _push(self.commands, brake if u < brake else traction if u > traction else u)
        self.expected = model_arx.predict(self.speeds, self.commands)
        predicted = free[0] + matrix[0, 0] * (u - previous)
        self.estimated = on_board_step(self.estimator, self.estimated, u, measured)
        return ControllerOutput(u, (predicted, error, self.bias, float(self.added),
                                    *on_board_estimates(self.estimator, self.estimated)))

    def _learn(self, target: float, measured: float) -> float:
        """The model's own one-step error (without the fed-back bias), fed back and to
        the online correction; with `hold`, nothing is learnt while the limiter holds
        the train (and the next step's error is not taken from a held one)."""
        if self.s.hold and holds(target, measured, self.limiter.settings):
            self.expected = None
            return 0.0
        error = 0.0
        if self.expected is not None:
            error = measured - self.expected
            self.bias += self.bias_gain * (error - self.bias)
            if self.model.observe(self.speeds, self.commands, error):
                self.added += 1
        return error

    def _berthing(self, free, matrix, reference):
        """The berthing mode: the predictions and targets up to the first target at or
        below gpc.berthing_speed (the stop), at least to the first prediction a move
        reaches. Beyond the stop the linear model rolls a braked train on backwards,
        and a target of 0 there would ease the braking into the mark."""
        below = np.flatnonzero(reference <= self.s.berthing_speed)
        if not len(below):
            return free, matrix, reference
        count = max(int(below[0]) + 1, self.model.delay + 1)
        return free[:count], matrix[:count], reference[:count]

    def _solve(self, hessian, gradient, previous: float, low: float, high: float) -> float:
        """The first move du(k) of the plan, the command kept in [low, high]."""
        if not self.s.constrained:
            return float(np.linalg.solve(hessian, -gradient)[0])
        # never infeasible: a bound the jerk limit cannot reach yet widens to what it can
        upper = np.maximum(high, previous - self.reach) - previous
        lower = np.minimum(low, previous + self.reach) - previous
        x, _, flag, _ = daqp.solve(hessian, gradient, self.cumulative,
                                   np.concatenate([self.move_limit, upper]),
                                   np.concatenate([-self.move_limit, lower]))
        if flag < 1:  # no solution reported: the closed form, clipped by the limiter
            return float(np.linalg.solve(hessian, -gradient)[0])
        return float(x[0])


def _build(values, context, limiter: CommandLimiter) -> GPC:
    kind = values["gpc.prediction"]
    settings = GPCSettings(values["gpc.horizon"], values["gpc.control_horizon"],
                           values["gpc.q"], values["gpc.r"], values["gpc.constrained"],
                           values["gpc.bias_filter"], values["gpc.berthing_speed"],
                           values["gpc.hold"])
    if values["controller.preview"] < settings.horizon:
        raise ScenarioError(f"gpc.horizon = {settings.horizon} needs controller.preview >= "
                            f"{settings.horizon} (it is {values['controller.preview']})")
    if kind == "mechanistic":
        model = MechanisticModel(context.train, context.period)
    else:
        model = model_for_run(values, context)
        if kind == "lssvm":
            model = LearnedModel(model.lssvm, values["gpc.correction"],
                                 values["gpc.correction_threshold"])
        else:
            model = MultiModel(model.lssvm.layout, model.arx_centres, model.arx_width,
                               model.arx_coefficients)
    return GPC(settings, model, context.period, limiter, context.train,
               values["plant.envelope"],
               on_board_estimator(values, context.period, context.line))


def model_for_run(values, context):
    """The model file of a run, checked against it: one line for a missing one, or one
    identified for another train preset or control period."""
    path = values["gpc.model"]
    if not path:
        raise ScenarioError(f"gpc.prediction {values['gpc.prediction']} needs gpc.model (a "
                            f"model file from scripts/identify.py)")
    model = load_model(path, values["gpc.window"])
    if abs(model.period - context.period) > 1e-9 * context.period:
        raise ScenarioError(f"model file {path} was identified at a {model.period:g} s period, "
                            f"the run steps at {context.period:g} s")
    train = model.train.get("plant.train", "")
    if train != values["plant.train"]:
        raise ScenarioError(f"model file {path} was identified on train {train or '(none)'!r}, "
                            f"the run uses {values['plant.train'] or '(none)'!r}")
    return model


GPC_CONTROLLER = Component(
    "gpc", "generalized predictive control on an LSSVM, mechanistic or multi-model (seed 001)",
    PARAMETERS, _build,
    (Output("predicted_speed", "m/s", "the model's prediction of y(k+1) under u(k)"),
     Output("model_error", "m/s", "one-step prediction error y(k) - y(k|k-1)"),
     Output("bias", "m/s", "filtered one-step residual fed back into the prediction"),
     Output("samples_added", "1", "samples the online correction has added so far"),
     *ESTIMATE_OUTPUTS),
    search_space=(("gpc.q", 0.1, 100.0), ("gpc.r", 1e-5, 1e-1), ("gpc.bias_filter", 0.0, 20.0)),
    # the mechanistic model needs no model file
    warm_up=(("gpc.prediction", "mechanistic"), ("gpc.horizon", 1), ("controller.preview", 1)),
    estimates=True)
