"""On-board estimation of the real train's mass, running resistance and actuator lag
(ROS-free).

What it estimates, and why in this form
---------------------------------------
The plant (core/train/plant.py) makes the real train differ from the nominal one by
three factors, and they enter differently:

* plant.resistance_factor r scales the basic (Davis) resistance: w0 = r (a + b v + c v^2),
  N/kN. The estimator carries r itself (a resistance scale), not a, b and c: over a
  run the regressors 1, v and v^2 are nearly collinear (on seed004-metro-ato's nominal
  run, moving steps, the normalised information matrix of (a, b, c) has a condition
  number of 913, seed003-maglev-ato's 1.8e3; v and v^2 correlate at 0.99), so three free
  coefficients wander along the poorly seen directions while one scale on the nominal
  curve is seen at every speed; it is also exactly how the studies vary the train.
* plant.mass_factor m enters only through the envelope. Forces are specific (N/kN):
  a command within the envelope is delivered as that specific force whatever the load
  (the traction is load-compensated), so dv/dt = xi (F - w0 - w_line) has no mass in it.
  The envelope is in kN and kW, so the real limits are the nominal ones (N/kN) over m.
  The estimator carries the inverse mass factor theta = 1/m: the applied force is then
  clamp(demand, low theta, high theta), linear in theta where the envelope binds (a
  factor m would divide); 1/m is also the one that enters Newton's law linearly.
  Consequence: the mass is seen only while the real train is at its envelope. On the
  shipped ATO runs only a heavy train gets there (metro, m = 1.3: ~11 s at full
  traction; maglev: ~21 s); a light or nominal train never does (the ATO plans at 90 %
  of the nominal envelope), so its mass estimate stays the load weighing's, with the
  load weighing's sigma: that is honest, not a fault (and all a controller needs: the
  envelope it may use is not below the nominal one).
* plant.lag_factor lambda scales the first-order lag's time constant. The estimator's
  actuator model runs at the estimated lag (its exact discretisation's decay and mean
  over the period at lambda tau), and carries the lag state's derivative by lambda
  through it: the lag shows wherever the command changes (the departure, every change
  of stage, the stop's jerk-limited braking), a 30 % slower lag being ~0.1 m/s of speed
  behind after a metro's change of 0.5 m/s^2, ten times the speed sensor's noise; it is
  seen within ~1-2 % by the end of the metro's acceleration. estimator.lag_sigma 0 (the
  default) keeps the nominal lag (a zero row and column of the covariance: exactly the
  three-state filter's bits). Why not on by default: with it the linear ADRC tracks slow
  actuators better, but some metro stops creep on for seconds and a light train's mass
  estimate drifts up under the brakes (docs/results.md, "The train learned on board").
  The dead time is not estimated: it moves by whole periods (the ring of pending
  commands), a discrete quantity an EKF cannot follow; its error shows as lag.

Filter: an extended Kalman filter on x = (v, theta, r, lambda), the speed a state
(m/s), theta, r and lambda random walks. Against recursive least squares with
exponential forgetting: RLS's covariance grows by one over its forgetting factor every
step whatever the data, so during a dwell, a cruise or a coast (no mass information for
most of a run) it winds up exponentially
and the next saturation makes the estimate jump; the KF's process noise adds a stated
drift per second (linear growth), takes the load weighing as a proper prior, and
freezing is simply skipping the update. The speed as a state, not a differentiated
acceleration: the sensor's noise (0.01 m/s) and resolution (0.01 m/s) over a 0.1 s period
are ~0.15 m/s^2 of acceleration noise against a 20 % resistance error of ~0.015 m/s^2;
the filter compares the measured speed with the speed the model integrates (a
regression on speed increments, optimally weighted), so the noise does not grow with
the differencing and the innovations stay white. The uncertainty is the covariance
diagonal (sigma of theta, r and lambda; mass_sigma ~ theta_sigma / theta^2).

Per control period (estimator_step): the command just sent enters the estimator's own
copy of the ATO's actuator model (train_model.nominal_advance's dead-time ring, then
nominal_act's lag at the estimated time constant and traction cut in neutral sections,
on a model without the nominal envelope), the estimated envelope (nominal / m) cutting
it where the plant does, at the lag's input, and again at the output's mean; the force's
derivatives by theta and lambda go through the lag with it (a lag that creeps up to the
envelope is informative too). The next
step's measured speed closes the period: predict
(v + h xi (F(theta) - r w0(v) - w_line), midpoint in v), then update. Frozen (no update,
no drift; the speed state reset to the measurement): a period that starts or ends below
estimator.min_speed (standstill, holding brake, the last metres of a stop: the
brakes, not the model, set the acceleration) or whose pantograph comes within
estimator.neutral_margin of a neutral section's edge (whether traction was cut is then
unsure by the dead reckoning's error).

Units: speeds m/s, forces and resistances N/kN (specific, as the whole core), positions
m, theta, r and lambda dimensionless; the covariance is over (v m/s, theta, r, lambda).

How the controllers use it
-------------------------
* on_board_estimator(values, period, line, model) builds it once per run (OnBoardEstimator
  in the controller's settings, the EstimatorState in its state): the nominal train
  (`model`: the controller's nominal model, whose line tables it shares), the load
  weighing's train.mass_reading (scenario.weighed: the plant side's load cell, the one
  place the real mass is read) as the mass prior, its uncertainty estimator.mass_sigma (else
  the load weighing's error train.load_weighing_error).
  Off (estimator.enabled false), its settings and its state are None: compiled code
  prunes the estimator's branches while compiling (numba drops a branch on an argument
  that is None), so a run without it compiles without its code and carries none of its
  arrays from step to step.
* Each period, after the command u is sent: state = on_board_step(estimator, state, u,
  measured_speed) (estimator_step when on, else None kept).
* The resistance scale (on_board_scale: 1 off) enters train_model.known_resistance as its
  basic_scale (the linear ADRC's feedforward, observer input and prediction; the PID's
  feedforward; the GPC's prediction); estimated_force_limits(settings, state, speed) is
  the envelope of the GPC's constraints; on_board_actuator is the actuator of the linear
  ADRC's nominal model (its delay-aware prediction and its observer's input:
  train_model.nominal_act): its envelope scaled by the controller's model's mass over the
  estimated one, and the estimated lag. Off, it is the model's own (a scale of 1, which
  multiplies exactly, and the model's lag), so a controller with the estimator off gives
  the bits it gave before it had one. The GPC keeps the nominal lag (its prediction matrices
  are built once per run).
* on_board_estimates(estimator, state) are the controllers' recorded outputs
  ESTIMATE_OUTPUTS: estimates(state), off the departure's throughout.
* estimate_series(settings, state, commands, measured_speeds) runs it over recorded
  series (studies: scripts/estimator_accuracy.py); compiled_estimate_rows is the same
  loop compiled.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import compiled, jitable
from ..base.spec import PROFILE_NODES, param
from ..base.registry import Output
from ..train.line import Line, belt_resistance, in_neutral_section
from ..train.plant import Envelope, TrainParameters, basic_resistance, force_limits
from .limiter import clamp
from .train_model import (Actuator, NominalModel, NominalState, dead_time_steps,
                          known_resistance, lag_coefficients, model_actuator, nominal_act,
                          nominal_train)

PARAMETERS = (
    param("estimator.enabled", False, "estimate the real train's mass, running resistance "
          "and actuator lag on board, for the controllers that use it (linear_adrc, pid, gpc: "
          "the resistance in their models and feedforward, the estimated envelope in the "
          "GPC's constraints and the linear ADRC's nominal actuator, the estimated lag in "
          "the latter); off: the load weighing's mass and the nominal resistance and lag",
          "controller"),
    param("estimator.mass_sigma", 0.0, "prior uncertainty (1 sigma) of the mass, relative to "
          "train.mass_reading: the range a train with no load weighing may weigh, or by which "
          "its load cells may read wrong (0 = train.load_weighing_error, the load weighing's "
          "error)", PROFILE_NODES, 0.0, 5.0),
    param("estimator.resistance_sigma", 0.2, "prior uncertainty (1 sigma) of the running "
          "resistance over the nominal", "controller", 0.001, 5.0),
    param("estimator.speed_noise", 0.01, "speed sensor noise and resolution together, "
          "1 sigma, m/s", "controller", 1e-5, 10.0),
    param("estimator.acceleration_noise", 0.02, "acceleration the model does not explain "
          "(lag, dead time, envelope within the period), 1 sigma, m/s^2", "controller",
          1e-6, 10.0),
    param("estimator.mass_drift", 1e-4, "random-walk drift of the inverse mass factor, "
          "per square-root second", "controller", 0.0, 1.0),
    param("estimator.resistance_drift", 1e-3, "random-walk drift of the resistance scale, "
          "per square-root second", "controller", 0.0, 1.0),
    param("estimator.lag_sigma", 0.0, "prior uncertainty (1 sigma) of the actuator's lag "
          "over the nominal (plant.actuator_lag), which the estimator then estimates and the "
          "linear ADRC's model takes (0.2 a range that covers +-40 %); 0: not estimated, the "
          "nominal lag kept", "controller", 0.0, 5.0),
    param("estimator.lag_drift", 1e-3, "random-walk drift of the lag factor, per "
          "square-root second", "controller", 0.0, 1.0),
    param("estimator.min_speed", 1.0, "below this speed (standstill, holding brake, the "
          "last metres of a stop) the estimates are frozen, m/s", "controller", 0.0, 100.0),
    param("estimator.gate", 0.0, "a period whose measured speed is more than this many "
          "sigmas of its innovation off the prediction is not learned from (the wheels "
          "slipping or sliding on a poor rail give less than the train asked: read as the "
          "train's, the resistance and lag ran to their bounds); its speed is taken, the "
          "estimates kept; 0: every period learned from", "controller", 0.0, 100.0),
    param("estimator.neutral_margin", 5.0, "estimates frozen while the pantograph is this "
          "close to a neutral section's edge, m", "controller", 0.0, 1000.0),
)

# Bounds on the estimates: the schema's range of plant.mass_factor and resistance_factor.
LOWEST_FACTOR, HIGHEST_FACTOR = 0.1, 10.0
SPEED, INVERSE_MASS, RESISTANCE, LAG = 0, 1, 2, 3  # the covariance's rows
STATES = 4


class EstimatorSettings(NamedTuple):
    """What the run fixes for the estimator."""

    actuator: NominalModel     # the nominal train and line, its actuator without envelope
    envelope: Envelope         # the nominal envelope (kN, kW; weight kN)
    limited: bool              # the train has an envelope
    speed_variance: float      # (m/s)^2, of a speed reading
    gate_squared: float        # estimator.gate^2: innovations^2 an update takes, in
                               # innovation variances (inf: any)
    speed_drift: float         # (m/s)^2 per period, the unexplained acceleration's
    inverse_mass_drift: float  # per period, variance added to theta
    resistance_drift: float    # per period, variance added to r
    lag_drift: float           # per period, variance added to the lag factor
    nominal_lag: float         # s, the nominal actuator lag
    lag_estimated: bool        # estimator.lag_sigma > 0 and the train has a lag
    min_speed: float           # m/s, below it frozen
    neutral_margin: float      # m, frozen this close to a neutral section's edge
    dead_time_steps: int       # periods a command waits before it acts


class EstimatorState(NamedTuple):
    """What the estimator carries from one period to the next."""

    speed: float               # m/s, filtered speed at the start of the open period
    inverse_mass: float        # theta = 1 / mass factor (nominal mass over the real)
    resistance_scale: float    # r = real basic resistance over the nominal
    lag_factor: float          # lambda = real actuator lag over the nominal
    covariance: np.ndarray     # 4 x 4 over (speed m/s, theta, r, lambda)
    actuator: NominalState     # dead time, lag (N/kN), dead-reckoned position (m)
    demand: float              # N/kN, mean lagged command over the open period (no envelope
                               # at the lag's output)
    demand_by_mass: float      # N/kN, its derivative by theta (where the envelope cut the input)
    lag_by_mass: float         # N/kN, the lag state's derivative by theta
    demand_by_lag: float       # N/kN, the demand's derivative by lambda
    lag_by_lag: float          # N/kN, the lag state's derivative by lambda
    line_resistance: float     # N/kN, gradient + curve + tunnel at the open period's start
    informative: bool          # the open period started moving and clear of neutral edges
    updates: int               # periods that updated the estimates so far


def load_weighing(mass_factor: float, relative_error: float, seed: int) -> float:
    """The load-weighing reading at departure: the real mass factor (plant.mass_factor)
    with a relative error drawn from a normal of sigma `relative_error`, seeded."""
    draw = float(np.random.default_rng(seed).standard_normal())
    return mass_factor * max(1.0 + relative_error * draw, LOWEST_FACTOR)


def mass_prior_sigma(values) -> float:
    """The mass prior's relative uncertainty, 1 sigma: estimator.mass_sigma, else the load
    weighing's error (train.load_weighing_error)."""
    return values["estimator.mass_sigma"] or values["train.load_weighing_error"]


def estimator_settings(values, train: TrainParameters, period: float,
                       line: Line | None = None, model: NominalModel | None = None
                       ) -> EstimatorSettings:
    """From the run's estimator.* `values` and the nominal `train` (what the ATO knows) on
    `line`; `model`: the controller's nominal model of them, whose line tables the
    estimator's own model shares (else built)."""
    unlimited = dataclasses.replace(train, **{name: math.inf for name in (
        "max_traction_force", "max_traction_power", "max_brake_force", "max_brake_power")})
    if model is None:
        model = nominal_train(unlimited, period, 0.0, line)[0]
    lag_estimated = values["estimator.lag_sigma"] > 0.0 and train.actuator_lag > 0.0
    return EstimatorSettings(
        model._replace(train=unlimited.constants()), train.envelope, train.limited,
        values["estimator.speed_noise"] ** 2,
        values["estimator.gate"] ** 2 if values["estimator.gate"] > 0.0 else math.inf,
        (values["estimator.acceleration_noise"] * period) ** 2,
        values["estimator.mass_drift"] ** 2 * period,
        values["estimator.resistance_drift"] ** 2 * period,
        values["estimator.lag_drift"] ** 2 * period if lag_estimated else 0.0,
        train.actuator_lag, lag_estimated, values["estimator.min_speed"],
        values["estimator.neutral_margin"], dead_time_steps(train, period))


def estimator_start(settings: EstimatorSettings | None, mass_reading: float,
                    relative_error: float, resistance_sigma: float, lag_sigma: float,
                    position: float = 0.0, speed: float = 0.0) -> EstimatorState:
    """The state at departure from `position` (m) at `speed` (m/s): the mass prior from
    the load weighing (`mass_reading`, its `relative_error` 1 sigma), the resistance and
    lag priors the nominal ones with `resistance_sigma` and `lag_sigma` (the lag's 0 when
    the settings do not estimate it); without `settings`, the priors alone (what
    estimates() reads: no speed variance, no dead time)."""
    inverse_mass = 1.0 / mass_reading
    covariance = np.zeros((STATES, STATES))
    covariance[SPEED, SPEED] = settings.speed_variance if settings is not None else 0.0
    covariance[INVERSE_MASS, INVERSE_MASS] = (relative_error * inverse_mass) ** 2
    covariance[RESISTANCE, RESISTANCE] = resistance_sigma ** 2
    if settings is None or settings.lag_estimated:
        covariance[LAG, LAG] = lag_sigma ** 2
    ring = np.zeros(settings.dead_time_steps if settings is not None else 0)
    return EstimatorState(speed, inverse_mass, 1.0, 1.0, covariance,
                          NominalState(0.0, position, ring, 0), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                          False, 0)


def estimator_of(values, train: TrainParameters, period: float, mass_reading: float,
                 line: Line | None = None, position: float = 0.0, speed: float = 0.0,
                 model: NominalModel | None = None
                 ) -> tuple[EstimatorSettings, EstimatorState]:
    """Settings and departure state (from `position` m at `speed` m/s) from the run's
    estimator.* `values`, the nominal `train` (`model`, as for estimator_settings) and the
    load weighing's `mass_reading` (load_weighing), its uncertainty mass_prior_sigma."""
    settings = estimator_settings(values, train, period, line, model)
    return settings, estimator_start(settings, mass_reading, mass_prior_sigma(values),
                                     values["estimator.resistance_sigma"],
                                     values["estimator.lag_sigma"], position, speed)


@jitable
def estimator_step(settings: EstimatorSettings, state: EstimatorState, command: float,
                   measured_speed: float) -> EstimatorState:
    """One control period: `measured_speed` (m/s) closes the period the last command
    acted over (an update, or frozen), then `command` (N/kN, just sent) opens the next."""
    learned = state.informative and measured_speed >= settings.min_speed
    if learned:  # an update, unless the speed is beyond the gate
        learned, speed, inverse_mass, resistance_scale, lag_factor, covariance = (
            _closed_period(settings, state, measured_speed))
    if not learned:  # no information: the estimates and their covariance kept, the speed
        # measured
        speed, inverse_mass, resistance_scale, lag_factor = (
            measured_speed, state.inverse_mass, state.resistance_scale, state.lag_factor)
        covariance = _frozen_covariance(settings, state.covariance)
    updates = state.updates + 1 if learned else state.updates
    # dead reckoning by the trapezoid, now the period's end speed is known (the
    # actuator model steps by its start speed: ~1 m behind after an acceleration)
    ended = state.actuator
    ended = NominalState(ended.lag_state, ended.position + 0.5 * settings.actuator.period * (
        speed - state.speed), ended.pending, ended.oldest)
    opened = _open_period(settings, ended, state, command, speed, inverse_mass, lag_factor)
    return EstimatorState(speed, inverse_mass, resistance_scale, lag_factor, covariance,
                          opened.actuator, opened.demand, opened.demand_by_mass,
                          opened.lag_by_mass, opened.demand_by_lag, opened.lag_by_lag,
                          opened.line_resistance, opened.informative, updates)


@jitable
def estimated_mass_factor(state: EstimatorState) -> tuple[float, float]:
    """(real mass over the nominal, its sigma): 1 / theta, sigma_theta / theta^2."""
    theta = state.inverse_mass
    return 1.0 / theta, math.sqrt(state.covariance[INVERSE_MASS, INVERSE_MASS]) / (theta * theta)


@jitable
def estimated_resistance_scale(state: EstimatorState) -> tuple[float, float]:
    """(real basic resistance over the nominal, its sigma)."""
    return state.resistance_scale, math.sqrt(state.covariance[RESISTANCE, RESISTANCE])


@jitable
def estimated_lag_factor(state: EstimatorState) -> tuple[float, float]:
    """(real actuator lag over the nominal, its sigma)."""
    return state.lag_factor, math.sqrt(state.covariance[LAG, LAG])


@jitable
def estimated_resistance(settings: EstimatorSettings, state: EstimatorState, speed: float,
                         position: float) -> float:
    """Basic (scaled by the estimate) plus line resistance at `speed` (m/s) with the head
    at `position` (m), N/kN: what train_model.known_resistance gives for the nominal."""
    return known_resistance(settings.actuator, speed, position, state.resistance_scale)


@jitable
def estimated_force_limits(settings: EstimatorSettings, state: EstimatorState, speed: float
                           ) -> tuple[float, float]:
    """(most negative, most positive) specific force the real train can apply at `speed`
    as estimated (the nominal envelope over the mass factor), N/kN; infinite without one."""
    if not settings.limited:
        return -math.inf, math.inf
    low, high = force_limits(speed, settings.envelope)
    return low * state.inverse_mass, high * state.inverse_mass


@jitable
def _applied(settings: EstimatorSettings, state: EstimatorState, speed: float
             ) -> tuple[float, float, float]:
    """(the force the estimated envelope lets the open period's demand apply at `speed`,
    N/kN; its derivatives by theta, the nominal limit where the envelope binds, else the
    demand's, and by lambda, 0 where the envelope binds)."""
    demand, inverse_mass = state.demand, state.inverse_mass
    if not settings.limited:
        return demand, 0.0, state.demand_by_lag
    low, high = force_limits(speed, settings.envelope)
    if demand > high * inverse_mass:
        return high * inverse_mass, high, 0.0
    if demand < low * inverse_mass:
        return low * inverse_mass, low, 0.0
    return demand, state.demand_by_mass, state.demand_by_lag


@jitable
def _predict(settings: EstimatorSettings, state: EstimatorState
             ) -> tuple[float, tuple[float, float, float, float]]:
    """The speed at the end of the open period and its derivatives by (v, theta, r, lambda)
    at the start: the acceleration taken at the period's midpoint speed (the resistance
    and the power limit move with the speed within it)."""
    train = settings.actuator.train
    h, xi = settings.actuator.period, train.xi
    scale, speed = state.resistance_scale, state.speed
    force, _, _ = _applied(settings, state, speed)
    basic = basic_resistance(speed, train.davis_a, train.davis_b, train.davis_c)
    middle = speed + 0.5 * h * xi * (force - scale * basic - state.line_resistance)
    force, force_by_theta, force_by_lag = _applied(settings, state, middle)
    basic = basic_resistance(middle, train.davis_a, train.davis_b, train.davis_c)
    slope = train.davis_b + 2.0 * train.davis_c * abs(middle)  # d w0 / dv
    predicted = speed + h * xi * (force - scale * basic - state.line_resistance)
    # the transition's first row, by (v, theta, r, lambda)
    return predicted, (1.0 - h * xi * scale * slope, h * xi * force_by_theta,
                       -h * xi * basic, h * xi * force_by_lag)


@jitable
def _closed_period(settings: EstimatorSettings, state: EstimatorState, measured: float
                   ) -> tuple[bool, float, float, float, float, np.ndarray]:
    """The Kalman filter's prediction over the period and its update by the `measured`
    speed: (within the gate, speed, theta, r, lambda, covariance; the rest of the tuple
    meaningless outside the gate). Written out (the transition only has a
    first row to fill), so Python and compiled code do the same operations, on tuples and
    one new array (a small array's allocation costs the compiled step more than its
    arithmetic); a lag not estimated has a zero row and column, which add exact zeros."""
    predicted, by = _predict(settings, state)
    p = state.covariance
    row = (_row_entry(by, p, SPEED), _row_entry(by, p, INVERSE_MASS),  # first row of A P
           _row_entry(by, p, RESISTANCE), _row_entry(by, p, LAG))
    covariance = p.copy()  # the prior, then the posterior in place
    covariance[SPEED, SPEED] = (row[SPEED] * by[SPEED] + row[INVERSE_MASS] * by[INVERSE_MASS]
                                + row[RESISTANCE] * by[RESISTANCE] + row[LAG] * by[LAG]
                                + settings.speed_drift)
    for i in range(1, STATES):
        covariance[SPEED, i] = row[i]
        covariance[i, SPEED] = row[i]
    covariance[INVERSE_MASS, INVERSE_MASS] += settings.inverse_mass_drift
    covariance[RESISTANCE, RESISTANCE] += settings.resistance_drift
    covariance[LAG, LAG] += settings.lag_drift
    first = (covariance[SPEED, SPEED], covariance[SPEED, INVERSE_MASS],  # the prior's
             covariance[SPEED, RESISTANCE], covariance[SPEED, LAG])    # first row
    innovation_variance = first[SPEED] + settings.speed_variance
    innovation = measured - predicted
    if innovation * innovation > settings.gate_squared * innovation_variance:
        return False, predicted, state.inverse_mass, state.resistance_scale, \
            state.lag_factor, p
    gain = (first[SPEED] / innovation_variance, first[INVERSE_MASS] / innovation_variance,
            first[RESISTANCE] / innovation_variance, first[LAG] / innovation_variance)
    for i in range(STATES):
        for j in range(i, STATES):  # the upper triangle, mirrored: symmetric to the bit
            covariance[i, j] = covariance[i, j] - gain[i] * first[j]
            covariance[j, i] = covariance[i, j]
    inverse_mass = clamp(state.inverse_mass + gain[INVERSE_MASS] * innovation,
                         1.0 / HIGHEST_FACTOR, 1.0 / LOWEST_FACTOR)
    resistance_scale = clamp(state.resistance_scale + gain[RESISTANCE] * innovation,
                             LOWEST_FACTOR, HIGHEST_FACTOR)
    lag_factor = clamp(state.lag_factor + gain[LAG] * innovation, LOWEST_FACTOR,
                       HIGHEST_FACTOR)
    return (True, predicted + gain[SPEED] * innovation, inverse_mass, resistance_scale,
            lag_factor, covariance)


@jitable
def _row_entry(by: tuple[float, float, float, float], p: np.ndarray, j: int) -> float:
    """Entry `j` of the transition's first row (`by`) times the covariance `p`."""
    return (by[SPEED] * p[SPEED, j] + by[INVERSE_MASS] * p[INVERSE_MASS, j]
            + by[RESISTANCE] * p[RESISTANCE, j] + by[LAG] * p[LAG, j])


@jitable
def _frozen_covariance(settings: EstimatorSettings, covariance: np.ndarray) -> np.ndarray:
    """The parameters' covariance kept, the speed's that of a reading and unrelated."""
    frozen = covariance.copy()
    for i in range(STATES):
        frozen[SPEED, i] = 0.0
        frozen[i, SPEED] = 0.0
    frozen[SPEED, SPEED] = settings.speed_variance
    return frozen


class OpenedPeriod(NamedTuple):
    """What a command sent opens: the actuator model over the coming period."""

    actuator: NominalState     # stepped over the period
    demand: float              # N/kN, its mean force before the output's envelope
    demand_by_mass: float      # its derivatives by theta and lambda
    lag_by_mass: float         # the lag state's, after the period
    demand_by_lag: float
    lag_by_lag: float
    line_resistance: float     # N/kN, at the period's start
    informative: bool          # whether the period may inform


@jitable
def _open_period(settings: EstimatorSettings, actuator: NominalState, state: EstimatorState,
                 command: float, speed: float, inverse_mass: float, lag_factor: float
                 ) -> OpenedPeriod:
    """`command` sent at `speed` opens the next period, the actuator model (`actuator`,
    the derivatives `state` carries) at the estimated envelope (`inverse_mass`) and lag
    (`lag_factor`)."""
    model = settings.actuator
    position = actuator.position
    after, demand, demand_by_mass, lag_by_mass, demand_by_lag, lag_by_lag = (
        _actuator_period(settings, actuator, state, command, speed, inverse_mass, lag_factor))
    line_resistance = 0.0
    if model.on_line:
        line_resistance = belt_resistance(model.line, position, model.train.length)
    informative = speed >= settings.min_speed and not _near_neutral_edge(
        settings, position, speed)
    return OpenedPeriod(after, demand, demand_by_mass, lag_by_mass, demand_by_lag, lag_by_lag,
                        line_resistance, informative)


@jitable
def _actuator_period(settings: EstimatorSettings, actuator: NominalState,
                     state: EstimatorState, command: float, speed: float, inverse_mass: float,
                     lag_factor: float
                     ) -> tuple[NominalState, float, float, float, float, float]:
    """train_model.nominal_advance with the estimated envelope at the lag's input (where
    the plant cuts the command) and the estimated lag: (the actuator after the period,
    its mean force before the envelope at the output N/kN, its derivative by theta, the
    lag state's, the mean force's by lambda, the lag state's), the derivatives carried
    through the lag's exact discretisation (decay and spread 0 without a lag)."""
    model = settings.actuator
    decay, spread, decay_by_lag, spread_by_lag = _lag_at(settings, lag_factor)
    pending, oldest = actuator.pending.copy(), actuator.oldest  # the state's is not changed
    if len(pending):
        command, pending[oldest] = pending[oldest], command
        oldest = (oldest + 1) % len(pending)
    input_by_mass = 0.0
    if settings.limited:
        low, high = force_limits(speed, settings.envelope)
        if command > high * inverse_mass:
            command, input_by_mass = high * inverse_mass, high
        elif command < low * inverse_mass:
            command, input_by_mass = low * inverse_mass, low
    lag_state, demand = nominal_act(model, actuator.lag_state, command, speed,
                                    actuator.position, Actuator(1.0, decay, spread))
    if model.neutral and command > 0.0 and in_neutral_section(
            model.line, actuator.position - model.pantograph_offset):
        command, input_by_mass = 0.0, 0.0  # traction cut: nominal_act took the command to 0
    change = actuator.lag_state - command
    demand_by_mass = input_by_mass + (state.lag_by_mass - input_by_mass) * spread
    demand_by_lag = state.lag_by_lag * spread + change * spread_by_lag
    if demand == 0.0:  # cut in a neutral section: no force, nothing to derive
        demand_by_mass, demand_by_lag = 0.0, 0.0
    lag_by_mass = input_by_mass + (state.lag_by_mass - input_by_mass) * decay
    lag_by_lag = state.lag_by_lag * decay + change * decay_by_lag
    after = NominalState(lag_state, actuator.position + model.period * speed, pending, oldest)
    return after, demand, demand_by_mass, lag_by_mass, demand_by_lag, lag_by_lag


@jitable
def _lag_at(settings: EstimatorSettings, lag_factor: float
            ) -> tuple[float, float, float, float]:
    """The lag's decay and spread at `lag_factor` times the nominal, and their derivatives
    by the factor; the nominal's and zeros when the lag is not estimated."""
    model = settings.actuator
    if not settings.lag_estimated:
        return model.decay, model.spread, 0.0, 0.0
    lag = settings.nominal_lag * lag_factor
    decay, spread = lag_coefficients(model.period, lag)
    # decay = exp(-h / (lambda tau)), spread = lambda tau (1 - decay) / h
    return (decay, spread, decay * model.period / (lag_factor * lag),
            (spread - decay) / lag_factor)


@jitable
def _near_neutral_edge(settings: EstimatorSettings, position: float, speed: float) -> bool:
    """Whether a neutral section's edge lies within the margin of the pantograph's path
    over the period (then whether traction was cut is unsure)."""
    model = settings.actuator
    if not model.neutral:
        return False
    start = position - model.pantograph_offset
    end = start + model.period * speed
    margin = settings.neutral_margin
    inside = in_neutral_section(model.line, start)
    return (in_neutral_section(model.line, start - margin) != inside
            or in_neutral_section(model.line, end) != inside
            or in_neutral_section(model.line, end + margin) != inside)


class OnBoardEstimator(NamedTuple):
    """The estimator as a controller carries it in its settings (its state, None when off,
    in the controller's state): off, the controller runs as without one, to the bit, and
    reports the departure's estimates throughout."""

    settings: EstimatorSettings | None  # None: off
    departure: tuple[float, float, float, float, float, float]  # estimates() at departure
    model_mass: float  # the mass the controller's nominal model is at, over the nominal


ESTIMATE_OUTPUTS = (
    Output("mass_factor", "1", "the real mass over the nominal as estimated on board (the "
           "load weighing's until the train runs at its envelope)"),
    Output("mass_sigma", "1", "its uncertainty, 1 sigma"),
    Output("resistance_scale", "1", "the real basic running resistance over the nominal, as "
           "estimated on board"),
    Output("resistance_sigma", "1", "its uncertainty, 1 sigma"),
    Output("lag_factor", "1", "the real actuator lag over the nominal, as estimated on board "
           "(the nominal with estimator.lag_sigma 0)"),
    Output("lag_sigma", "1", "its uncertainty, 1 sigma"),
)
ESTIMATE_COLUMNS = tuple(output.name for output in ESTIMATE_OUTPUTS)
ESTIMATED_FACTORS = {  # an estimate -> (its sigma, the real train's factor it estimates)
    "mass_factor": ("mass_sigma", "plant.mass_factor"),
    "resistance_scale": ("resistance_sigma", "plant.resistance_factor"),
    "lag_factor": ("lag_sigma", "plant.lag_factor"),
}


def on_board_estimator(values, period: float, line: Line | None = None,
                       model: NominalModel | None = None
                       ) -> tuple[OnBoardEstimator, EstimatorState | None]:
    """A controller's estimator from the run's values: the nominal train (plant.*) on
    `line` (`model`: the controller's nominal model of them, its line tables shared), the
    load weighing's train.mass_reading as its mass prior, departing from
    plant.initial_position (m); off (estimator.enabled false), its settings and state None
    and the departure's estimates (the priors alone: no model built)."""
    if not values["estimator.enabled"]:
        prior = estimator_start(None, values["train.mass_reading"], mass_prior_sigma(values),
                                values["estimator.resistance_sigma"],
                                values["estimator.lag_sigma"])
        return OnBoardEstimator(None, estimates(prior), 1.0), None
    settings, state = estimator_of(values, TrainParameters.from_values(values), period,
                                   values["train.mass_reading"], line,
                                   values["plant.initial_position"], 0.0, model)
    model_mass = max(values["train.mass_reading"], 1.0)  # config/context.ato_train's
    return OnBoardEstimator(settings, estimates(state), model_mass), state


@jitable
def on_board_step(estimator: OnBoardEstimator, state: EstimatorState | None, command: float,
                  measured_speed: float) -> EstimatorState | None:
    """estimator_step when the estimator is on; else None, as it was (compiled code prunes
    the step while compiling a run without the estimator)."""
    if state is None:
        return state
    return estimator_step(estimator.settings, state, command, measured_speed)


@jitable
def on_board_scale(state: EstimatorState | None) -> float:
    """The resistance scale as estimated on board; 1 with the estimator off."""
    if state is None:
        return 1.0
    return state.resistance_scale


@jitable
def on_board_actuator(estimator: OnBoardEstimator, state: EstimatorState | None,
                      model: NominalModel) -> Actuator:
    """The actuator of the controller's nominal `model` as estimated on board: its
    envelope over the model's (the model's mass over the estimated one) and, when the lag
    is estimated, its lag; the model's own (model_actuator) with the estimator off."""
    if state is None:
        return model_actuator(model)
    envelope_scale = estimator.model_mass * state.inverse_mass
    if not estimator.settings.lag_estimated:
        return Actuator(envelope_scale, model.decay, model.spread)
    decay, spread = lag_coefficients(model.period,
                                     estimator.settings.nominal_lag * state.lag_factor)
    return Actuator(envelope_scale, decay, spread)


@jitable
def on_board_estimates(estimator: OnBoardEstimator, state: EstimatorState | None
                       ) -> tuple[float, float, float, float, float, float]:
    """ESTIMATE_OUTPUTS' values: estimates(state), the departure's with the estimator off."""
    if state is None:
        return estimator.departure
    return estimates(state)


@jitable
def estimates(state: EstimatorState) -> tuple[float, float, float, float, float, float]:
    """ESTIMATE_OUTPUTS' values."""
    mass, mass_sigma = estimated_mass_factor(state)
    scale, scale_sigma = estimated_resistance_scale(state)
    lag, lag_sigma = estimated_lag_factor(state)
    return mass, mass_sigma, scale, scale_sigma, lag, lag_sigma


@jitable
def estimate_rows(settings: EstimatorSettings, state: EstimatorState, commands: np.ndarray,
                  measured_speeds: np.ndarray, rows: np.ndarray) -> EstimatorState:
    """The estimator over recorded series (step k: measured_speeds[k], then commands[k]):
    rows[k] the estimates after step k, ESTIMATE_COLUMNS; returns the last state."""
    for k in range(len(commands)):
        state = estimator_step(settings, state, commands[k], measured_speeds[k])
        estimated = estimates(state)
        for column in range(len(estimated)):
            rows[k, column] = estimated[column]
    return state


compiled_estimate_rows = compiled(estimate_rows)


def estimate_series(settings: EstimatorSettings, state: EstimatorState, commands,
                    measured_speeds, fast: bool = False
                    ) -> tuple[dict[str, np.ndarray], EstimatorState]:
    """({ESTIMATE_COLUMNS name: its value after each step}, the last state) over the
    series of a run (simulate()'s "command" and "measured_speed"); `fast`: compiled."""
    commands = np.asarray(commands, dtype=float)
    rows = np.empty((len(commands), len(ESTIMATE_COLUMNS)))
    run = compiled_estimate_rows if fast and compiled_estimate_rows is not None else (
        estimate_rows)
    state = run(settings, state, commands, np.asarray(measured_speeds, dtype=float), rows)
    return {name: rows[:, i] for i, name in enumerate(ESTIMATE_COLUMNS)}, state
