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
   brake envelope at the current speed, solved by Goldfarb and Idnani's dual
   active-set method (core/control/qp.py, compiled: a few microseconds at Nu = 3;
   DAQP, the solver it replaced, is its reference in tests/test_qp.py and
   benchmarks/benchmark_gpc.py). Unconstrained: the paper's closed form, then the
   limiter clips.
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
joins the model (core/control/lssvm.py: factor update, bounded window).

The mechanistic model: the nominal train's equations (the run context's train),
discretised exactly for a command held over the period (zero-order hold) through the
first-order lag tau, the dead time as an input delay, the resistance linearised at y(k)
and held over the period. With e = exp(-h/tau), c1 = tau (1 - e) / h, G = h xi and
u_d(k) the command acting over [k, k+1] (u(k - dead)):
    F(k+1) = e F(k) + (1 - e) u_d(k)
    y(k+1) = y(k) + G (c1 F(k) + (1 - c1) u_d(k) - w0(y(k)))
and, F eliminated,
    y(k+1) = (1 + e) y(k) - e y(k-1) + G ((1 - c1) u_d(k) + (c1 - e) u_d(k-1)
             - w0(y(k)) + e w0(y(k-1))).

The step is compiled (core/control/gpc_steps.py: plain functions of its settings and
state NamedTuples, as every stepped kind), the node and the compiled loop running the
same code: deterministic, so a node and simulate() stay bit-identical.
"""

from __future__ import annotations

import numpy as np

from ..base.errors import ScenarioError
from ..base.registry import Component, Output
from ..base.spec import param
from ..base.units import KMH
from .estimation import ESTIMATE_OUTPUTS, on_board_estimator
from .gpc_steps import (GPC_STEPS, LEARNED, MECHANISTIC, MULTIMODEL, GPCSettings, GPCState,
                        MultiModel, Nominal)
from .limiter import CommandLimiter
from .lssvm import Layout, empty_dictionary, load_model
from .stepped import SteppedController
from .train_model import lag_coefficients

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
    param("gpc.constrained", True, "solve the input constraints as a QP (a dual active-set "
          "method); false = the paper's unconstrained closed form, clipped by the limiter",
          "controller"),
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


def _build(values, context, limiter: CommandLimiter) -> SteppedController:
    horizon, kind = values["gpc.horizon"], values["gpc.prediction"]
    if values["controller.preview"] < horizon:
        raise ScenarioError(f"gpc.horizon = {horizon} needs controller.preview >= "
                            f"{horizon} (it is {values['controller.preview']})")
    train, period = context.train, context.period
    if kind == "mechanistic":
        layout, dictionary = Layout(2, 2, round(train.dead_time / period)), empty_dictionary(4)
        multimodel = MultiModel(np.zeros(0), 1.0, np.zeros((0, 5)))
        history = layout.delay + 3
    else:
        model = model_for_run(values, context)
        layout, dictionary = model.lssvm.layout, model.lssvm.dictionary
        multimodel = MultiModel(model.arx_centres.copy(), model.arx_width,
                                model.arx_coefficients.copy())
        history = max(layout.speed_lags, layout.history + 1)
    if horizon <= layout.delay:
        raise ScenarioError(f"gpc.horizon = {horizon} does not reach past the model's input "
                            f"delay of {layout.delay} steps")
    estimator, estimated = on_board_estimator(values, period, context.line)
    settings = GPCSettings(
        horizon, min(values["gpc.control_horizon"], horizon), values["gpc.q"], values["gpc.r"],
        values["gpc.constrained"], _bias_gain(values["gpc.bias_filter"], period),
        values["gpc.berthing_speed"], values["gpc.hold"],
        {"lssvm": LEARNED, "mechanistic": MECHANISTIC, "multimodel": MULTIMODEL}[kind],
        layout.speed_lags, layout.command_lags, layout.delay,
        kind == "lssvm" and values["gpc.correction"], values["gpc.correction_threshold"],
        period, _nominal(train, period), multimodel, values["plant.envelope"],
        train.envelope, estimator)
    state = GPCState(np.zeros(history + 1), np.zeros(history + 1), False, 0.0, 0.0, 0,
                     dictionary, estimated)
    return SteppedController(GPC_STEPS, settings, limiter, state)


def _bias_gain(bias_filter: float, period: float) -> float:
    """The residual filter's gain per step (0: no feedback)."""
    return period / (bias_filter + period) if bias_filter else 0.0


def _nominal(train, period: float) -> Nominal:
    """The nominal train's constants for the mechanistic model (module docstring)."""
    lag, c1 = lag_coefficients(period, train.actuator_lag)
    return Nominal(train.xi, train.davis_a, train.davis_b, train.davis_c, lag, c1)


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
    # the mechanistic model needs no model file; 20 steps reach past a shipped dead time
    warm_up=(("gpc.prediction", "mechanistic"), ("gpc.horizon", 20), ("controller.preview", 20)),
    steps=GPC_STEPS, estimates=True)
