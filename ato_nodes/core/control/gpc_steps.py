"""The GPC's start and step (core/control/gpc.py: the method) as plain functions of
NamedTuples, compiled: GPCSettings what a run fixes, GPCState what it carries (the
histories, the fed-back residual, the LSSVM's Dictionary with its online corrections,
the on-board estimator's state). The node (SteppedController) and the compiled loop
(core/run/fast_loop.py) run the same compiled code: from Python gpc_step calls it
compiled, in the compiled loop it is compiled into the loop.

A step's arrays (the ARX model, the responses, the QP) are a few dozen floats, made
anew each step; the dictionary's are changed in place, the histories too.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import AVAILABLE, compiled, jitable, overload
from ..train.plant import Envelope, basic_resistance, force_limits
from .estimation import (EstimatorState, OnBoardEstimator, estimated_force_limits,
                         on_board_estimates, on_board_step)
from .limiter import LimiterSettings, clamp, holds, limit_command
from .lssvm import Dictionary, _add_sample, _linearise_dictionary
from .qp import SOLVED, cholesky, lower_solve, solve_qp, upper_solve, work_space
from .stepped import ControllerSteps

LEARNED, MECHANISTIC, MULTIMODEL = 0, 1, 2  # GPCSettings.prediction


class Nominal(NamedTuple):
    """The nominal train as the mechanistic model and the estimated resistance read it."""

    xi: float       # m/s^2 per N/kN
    davis_a: float  # N/kN
    davis_b: float  # N/kN per m/s
    davis_c: float  # N/kN per (m/s)^2
    lag: float      # exp(-h / tau), 0 without a lag
    c1: float       # tau (1 - lag) / h, 0 without a lag


class MultiModel(NamedTuple):
    """Linear ARX models around operating speeds, blended by Gaussian weights of y(k)."""

    centres: np.ndarray       # m/s
    width: float              # m/s
    coefficients: np.ndarray  # one row [c, a.., b..] per centre


class GPCSettings(NamedTuple):
    horizon: int           # P
    moves: int             # Nu, at most P
    q: float
    r: float
    constrained: bool
    bias_gain: float       # h / (bias_filter + h); 0: no feedback
    berthing_speed: float  # m/s, 0: the whole horizon (the paper's)
    hold: bool             # no learning while the limiter holds the train
    prediction: int        # LEARNED, MECHANISTIC or MULTIMODEL
    speed_lags: int        # na of the learned and multi-models
    command_lags: int      # nb of theirs
    delay: int             # the model's input delay, steps
    correct: bool          # online correction of the learned model
    threshold: float       # m/s, the one-step error beyond which a sample joins it
    period: float          # s
    nominal: Nominal
    multimodel: MultiModel
    envelope: bool         # the nominal train's envelope bounds the command
    train_envelope: Envelope
    estimator: OnBoardEstimator


class GPCState(NamedTuple):
    speeds: np.ndarray      # y history, newest last (y(k) after the push)
    commands: np.ndarray    # applied-command history, newest last
    expecting: bool         # `expected` holds a prediction (not before the first step)
    expected: float         # m/s, the model's prediction of the next y(k)
    bias: float             # m/s, the filtered one-step residual fed back
    added: int              # samples the online correction added
    model: Dictionary       # the learned model (empty for the other predictions)
    estimator: EstimatorState | None


@jitable
def _push(history: np.ndarray, value: float) -> None:
    """Drop the oldest entry, append the newest."""
    for i in range(len(history) - 1):
        history[i] = history[i + 1]
    history[-1] = value


@jitable
def _learned_arx(settings: GPCSettings, model: Dictionary, speeds: np.ndarray,
                 commands: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The LSSVM linearised at x(k+1) (speeds end with y(k), commands with u(k-1); u(k),
    not chosen yet, taken as u(k-1)) into (c, a, b)."""
    na, nb = settings.speed_lags, settings.command_lags
    x, gradient = np.empty(na + nb), np.empty(na + nb)
    for j in range(na):
        x[j] = speeds[len(speeds) - 1 - j]
    for j in range(nb):
        x[na + j] = commands[len(commands) - max(settings.delay + j, 1)]
    value = _linearise_dictionary(model, x, gradient)
    tangent = 0.0
    for j in range(na + nb):
        tangent += gradient[j] * x[j]
    a = gradient[:na].copy()
    a[0] += 1.0  # the model learns the increment y(k+1) - y(k)
    return value - tangent, a, gradient[na:].copy()


@jitable
def blended_row(m: MultiModel, speed: float) -> np.ndarray:
    """The blended coefficients [c, a.., b..] at this speed; far outside every centre,
    the nearest's."""
    count, columns = m.coefficients.shape
    weights = np.empty(count)
    for i in range(count):
        weights[i] = math.exp(-0.5 * ((speed - m.centres[i]) / m.width) ** 2)
    if not weights.sum() > 0.0:
        nearest = np.abs(speed - m.centres).min()
        for i in range(count):
            weights[i] = 1.0 if abs(speed - m.centres[i]) == nearest else 0.0
    total = weights.sum()
    row = np.zeros(columns)
    for k in range(columns):
        for i in range(count):
            row[k] += weights[i] * m.coefficients[i, k]
        row[k] /= total
    return row


@jitable
def _multimodel_arx(settings: GPCSettings, speed: float
                    ) -> tuple[float, np.ndarray, np.ndarray]:
    row, na = blended_row(settings.multimodel, speed), settings.speed_lags
    return row[0], row[1:1 + na].copy(), row[1 + na:].copy()


@jitable
def _mechanistic_arx(settings: GPCSettings, v: float) -> tuple[float, np.ndarray, np.ndarray]:
    """The nominal train's equations at y(k) (gpc.py: MechanisticModel)."""
    n, h = settings.nominal, settings.period
    e, c1, gain = n.lag, n.c1, h * n.xi
    slope = n.davis_b + 2.0 * n.davis_c * abs(v)  # dw0/dv, N/kN per m/s
    w0 = basic_resistance(v, n.davis_a, n.davis_b, n.davis_c) - slope * v
    if e == 0.0:
        return -gain * w0, np.array([1.0 - gain * slope]), np.array([gain])
    return (-gain * w0 * (1.0 - e), np.array([1.0 + e - gain * slope, -e + e * gain * slope]),
            np.array([gain * (1.0 - c1), gain * (c1 - e)]))


@jitable
def _linearise(settings: GPCSettings, model: Dictionary, speeds: np.ndarray,
               commands: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The prediction model as an ARX model (c, a, b) at the current regressor."""
    if settings.prediction == LEARNED:
        return _learned_arx(settings, model, speeds, commands)
    if settings.prediction == MULTIMODEL:
        return _multimodel_arx(settings, speeds[-1])
    return _mechanistic_arx(settings, speeds[-1])


@jitable
def _predict(c: float, a: np.ndarray, b: np.ndarray, delay: int, speeds: np.ndarray,
             commands: np.ndarray) -> float:
    """One step of the ARX model from histories ending with y(k) and u(k)."""
    value = c
    for j in range(1, len(a) + 1):
        value += a[j - 1] * speeds[len(speeds) - j]
    for j in range(1, len(b) + 1):
        value += b[j - 1] * commands[len(commands) - delay - j]
    return value


@jitable
def free_and_forced(c: float, a: np.ndarray, b: np.ndarray, delay: int, speeds: np.ndarray,
                    commands: np.ndarray, horizon: int, moves: int
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(free response y(k+1..k+P) with u held at u(k-1), step-response matrix
    G: P x Nu, G[j, i] the response at k+j+1 to a unit move at k+i, held) of the ARX
    model from the histories (speeds end with y(k), commands with u(k-1))."""
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


@jitable
def _learn(settings: GPCSettings, state: GPCState, target: float, measured: float,
           limits: LimiterSettings) -> tuple[float, float, int, Dictionary]:
    """(the model's own one-step error, without the fed-back bias; the bias and the
    corrections after it; the model): fed back and to the online correction, y(k)
    pushed. With `hold`, nothing is learnt while the limiter holds the train."""
    if (settings.hold and holds(target, measured, limits)) or not state.expecting:
        return 0.0, state.bias, state.added, state.model
    error = measured - state.expected
    bias = state.bias + settings.bias_gain * (error - state.bias)
    model, added = state.model, state.added
    if settings.prediction == LEARNED and settings.correct and abs(error) > settings.threshold:
        speeds, commands, na = state.speeds, state.commands, settings.speed_lags
        x = np.empty(na + settings.command_lags)  # x(k): speeds up to y(k-1)
        for j in range(na):
            x[j] = speeds[len(speeds) - 2 - j]
        for j in range(settings.command_lags):
            x[na + j] = commands[len(commands) - settings.delay - 1 - j]
        model, accepted = _add_sample(model, x, speeds[-1] - speeds[-2])
        added += accepted
    return error, bias, added, model


@jitable
def _resistance_change(settings: GPCSettings, estimated: EstimatorState | None, a: np.ndarray,
                       speed: float) -> float:
    """What the ARX constant gains from the estimated resistance (gpc.py's docstring);
    0 with the estimator off."""
    if estimated is None:
        return 0.0
    n = settings.nominal
    acceleration = -n.xi * (estimated.resistance_scale - 1.0) * basic_resistance(
        speed, n.davis_a, n.davis_b, n.davis_c)
    lags = 0.0
    for j in range(len(a)):
        lags += (j + 1) * a[j]
    return settings.period * acceleration * lags


@jitable
def _force_range(settings: GPCSettings, estimated: EstimatorState | None, speed: float
                 ) -> tuple[float, float]:
    """(brake, traction) the train can apply at this speed, N/kN: the nominal's, or as
    estimated on board (unbounded without an envelope)."""
    if not settings.envelope:
        return -math.inf, math.inf
    if estimated is not None:
        return estimated_force_limits(settings.estimator.settings, estimated, speed)
    return force_limits(speed, settings.train_envelope)


@jitable
def _predictions(settings: GPCSettings, horizon: np.ndarray) -> int:
    """The predictions the cost counts: all P, or in berthing mode those up to the first
    target at or below gpc.berthing_speed (the stop), at least to the first a move
    reaches. Beyond the stop the linear model rolls a braked train on backwards, and a
    target of 0 there would ease the braking into the mark."""
    if settings.berthing_speed > 0.0:
        for j in range(settings.horizon):
            if horizon[1 + j] <= settings.berthing_speed:
                return max(j + 1, settings.delay + 1)
    return settings.horizon


@jitable
def _cost(settings: GPCSettings, free: np.ndarray, matrix: np.ndarray, horizon: np.ndarray,
          count: int) -> tuple[np.ndarray, np.ndarray]:
    """(Hessian q G^T G + r I, gradient q G^T (free - r)) of the cost over the first
    `count` predictions."""
    moves = settings.moves
    hessian, gradient = np.zeros((moves, moves)), np.zeros(moves)
    for i in range(moves):
        for j in range(moves):
            value = 0.0
            for k in range(count):
                value += settings.q * matrix[k, i] * matrix[k, j]
            hessian[i, j] = value + (settings.r if i == j else 0.0)
        value = 0.0
        for k in range(count):
            value += settings.q * matrix[k, i] * (free[k] - horizon[1 + k])
        gradient[i] = value
    return hessian, gradient


@jitable
def _closed_form(hessian: np.ndarray, gradient: np.ndarray) -> float:
    """The first move of the unconstrained optimum -H^-1 g (H positive definite: r > 0)."""
    moves = len(gradient)
    factor, middle, move = np.zeros((moves, moves)), np.empty(moves), np.empty(moves)
    cholesky(hessian, factor, moves)
    lower_solve(factor, -gradient, middle, moves)
    upper_solve(factor, middle, move, moves)
    return move[0]


@jitable
def constraints(moves: int, previous: float, low: float, high: float, max_change: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, lower, upper) of the QP's constraints on the moves du: each move within the
    jerk limit (`max_change`, N/kN per step; 0: none), then the command u0 + C du inside
    [low, high]."""
    rate = max_change if max_change > 0.0 else math.inf
    rows = np.zeros((2 * moves, moves))
    lower, upper = np.empty(2 * moves), np.empty(2 * moves)
    for i in range(moves):
        rows[i, i] = 1.0
        rows[moves + i, :i + 1] = 1.0
        lower[i], upper[i] = -min(rate, 1e30), min(rate, 1e30)
        # never infeasible: a bound the jerk limit cannot reach yet widens to what it can
        reach = rate * (i + 1)
        upper[moves + i] = max(high, previous - reach) - previous
        lower[moves + i] = min(low, previous + reach) - previous
    return rows, lower, upper


@jitable
def first_move(settings: GPCSettings, hessian: np.ndarray, gradient: np.ndarray,
               previous: float, low: float, high: float, max_change: float) -> float:
    """The first move du(k) of the plan, the command kept in [low, high] and each move
    within the jerk limit (constraints())."""
    if not settings.constrained:
        return _closed_form(hessian, gradient)
    moves = settings.moves
    rows, lower, upper = constraints(moves, previous, low, high, max_change)
    move = np.empty(moves)
    if solve_qp(hessian, gradient, rows, lower, upper, move, work_space(moves)) != SOLVED:
        return _closed_form(hessian, gradient)  # the limiter clips it
    return move[0]


@jitable
def gpc_start(settings: GPCSettings, state: GPCState, target: float, measured: float,
              horizon) -> GPCState:
    """The histories as if the train had stood at `measured` under no command."""
    state.speeds[:] = measured
    state.commands[:] = 0.0
    return state


@jitable
def _gpc_step(settings: GPCSettings, state: GPCState, target: float, measured: float,
              horizon: np.ndarray, last: float, limits: LimiterSettings):
    """One step (gpc.py's docstring: 1 to 4); outputs predicted_speed, model_error, bias,
    samples_added and the estimates (ESTIMATE_OUTPUTS)."""
    if len(horizon) < settings.horizon + 1:
        raise ValueError("the GPC needs controller.preview >= gpc.horizon")
    speeds, commands = state.speeds, state.commands
    _push(speeds, measured)
    tracked = horizon[-1]  # r_k+N: the law's berth and hold rules read the horizon's end
    error, bias, added, model = _learn(settings, state, tracked, measured, limits)
    c, a, b = _linearise(settings, model, speeds, commands)
    c += _resistance_change(settings, state.estimator, a, measured)
    free, matrix = free_and_forced(c + bias, a, b, settings.delay, speeds, commands,
                                   settings.horizon, settings.moves)
    hessian, gradient = _cost(settings, free, matrix, horizon,
                              _predictions(settings, horizon))
    brake, traction = _force_range(settings, state.estimator, measured)
    move = first_move(settings, hessian, gradient, last, max(limits.u_min, brake),
                      min(limits.u_max, traction), limits.max_change)
    u = limit_command(last + move, tracked, measured, last, limits)
    # what the models see: the part of the command the train can apply (the nominal
    # envelope), as in identification
    _push(commands, clamp(u, brake, traction))
    expected = _predict(c, a, b, settings.delay, speeds, commands)
    predicted = free[0] + matrix[0, 0] * (u - last)
    estimator = on_board_step(settings.estimator, state.estimator, u, measured)
    return u, (predicted, error, bias, float(added)) + on_board_estimates(
        settings.estimator, estimator), GPCState(speeds, commands, True, expected, bias, added,
                                                 model, estimator)


compiled_step = compiled(_gpc_step) or _gpc_step


def gpc_step(settings: GPCSettings, state: GPCState, target: float, measured: float, horizon,
             last: float, limits: LimiterSettings):
    """ControllerSteps.step: from Python the compiled step (the horizon as an array), in
    compiled code the step itself."""
    return compiled_step(settings, state, target, measured,
                         np.asarray(horizon, dtype=np.float64), last, limits)


if AVAILABLE:
    @overload(gpc_step)
    def _compiled_gpc_step(settings, state, target, measured, horizon, last, limits):
        return lambda settings, state, target, measured, horizon, last, limits: _gpc_step(
            settings, state, target, measured, horizon, last, limits)


GPC_STEPS = ControllerSteps(gpc_start, gpc_step, GPCState)
