"""The ATO's own model of its train, for controllers that use it (ROS-free).

What an ATO knows before the run (the run context's nominal train and line),
stepped along with the real train from the commands it sends and the speeds it
measures:

* the actuator: the commands still inside the dead time, the first-order lag
  (its state, discretised exactly for a command held over the period), the
  traction and brake envelope at the speed, traction cut while the pantograph
  is inside a neutral section (as core/train/plant.py does to the real train);
* where the train is: dead reckoning from the measured speeds (the position
  only picks the gradient under the train, so centimetres of drift do not matter);
* the known resistance: basic (Davis) plus gradient, curve and tunnel of the belt.

It predicts the speed some steps ahead from the commands already sent (then the
last one held), which is what a controller facing dead time and lag must act on.
The model is a NominalModel (what the run fixes) and a NominalState (what moves),
stepped by jitable functions that the Python and the compiled loop both call.
The real train may differ (core/train/plant.py's plant.*_factor): the controller's
observer estimates what this model does not explain.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from ..train.line import (Line, LineTables, belt_resistance, in_neutral_section, line_arrays,
                          neutral_distance)
from ..train.plant import TrainConstants, TrainParameters, basic_resistance, force_limits
from .limiter import clamp


class NominalModel(NamedTuple):
    """What the ATO knows of its train and line before the run."""

    train: TrainConstants      # the nominal train
    pantograph_offset: float   # m behind the head
    period: float              # s
    decay: float               # the lag's decay over a period (0: no lag)
    spread: float              # the lag's mean over a period, as a share of the change
    line: LineTables           # the line's (empty: the open track)
    on_line: bool
    neutral: bool              # the line has neutral sections


class NominalState(NamedTuple):
    lag_state: float           # N/kN, the lag's output before the envelope
    position: float            # m, dead-reckoned
    pending: np.ndarray        # the commands inside the dead time (a ring, oldest first
    oldest: int                # at `oldest`)


def nominal_train(train: TrainParameters, period: float, position: float = 0.0,
                  line: Line | None = None) -> tuple[NominalModel, NominalState]:
    """The model of `train` on `line` and its state at the start, at `position`."""
    decay, spread = lag_coefficients(period, train.actuator_lag)
    model = NominalModel(train.constants(), train.pantograph_offset, period, decay, spread,
                         line_arrays(line), line is not None,
                         line is not None and bool(line.neutral_sections))
    return model, NominalState(0.0, position, np.zeros(dead_time_steps(train, period)), 0)


@jitable
def lag_coefficients(period: float, lag: float) -> tuple[float, float]:
    """A first-order `lag` (s; 0: none) over a `period` (s) with its input held: (its decay,
    its mean over the period as a share of the change), the lag's exact discretisation."""
    if lag <= 0.0:
        return 0.0, 0.0
    decay = math.exp(-period / lag)
    return decay, lag * (1.0 - decay) / period


class Actuator(NamedTuple):
    """The actuator a model acts with, as known on board: its envelope over the model's
    (1: the model's) and its lag's coefficients (lag_coefficients; the model's own:
    model_actuator). Scalars: a step passes them without the model's arrays."""

    envelope_scale: float
    decay: float
    spread: float


@jitable
def model_actuator(model: NominalModel) -> Actuator:
    """The model's own actuator: its envelope, its lag."""
    return Actuator(1.0, model.decay, model.spread)


def dead_time_steps(train: TrainParameters, period: float) -> int:
    """The periods a command waits inside `train`'s dead time before it acts."""
    return round(train.dead_time / period)


@jitable
def nominal_act(model: NominalModel, lag_state: float, command: float, speed: float,
                position: float, actuator: Actuator) -> tuple[float, float]:
    """One period with `command` reaching the lag: (next lag state, mean force N/kN); the
    envelope the model's times `actuator`'s scale, the lag `actuator`'s (the on-board
    estimates; model_actuator: the model's)."""
    train = model.train
    powered = True
    if model.neutral and command > 0.0 and in_neutral_section(
            model.line, position - model.pantograph_offset):
        command, powered = 0.0, False
    low, high = 0.0, 0.0
    if train.limited:
        low, high = force_limits(speed, train.envelope)
        low, high = low * actuator.envelope_scale, high * actuator.envelope_scale
        command = clamp(command, low, high)
    mean = command + (lag_state - command) * actuator.spread
    if train.limited:
        mean = clamp(mean, low, high)
    if not powered and mean > 0.0:
        mean = 0.0
    return command + (lag_state - command) * actuator.decay, mean


@jitable
def neutral_ceiling(model: NominalModel, state: NominalState, speed: float,
                    max_change: float) -> float:
    """The most traction a command sent now may ask, N/kN (inf: no bound), so that none
    is commanded while the pantograph is inside a neutral section, nor acts there: a
    command acts after the dead time, for a period, so it asks none once the pantograph
    (dead-reckoned, at `speed`) reaches a section within the dead time and a period;
    before that at most what the jerk limit (`max_change` per period; 0: none) can still
    take off by then, so that the cut is in place, without a jump, as the pantograph
    enters. Released once the (dead-reckoned) pantograph has left the section."""
    if not model.neutral:
        return math.inf
    distance = neutral_distance(model.line, state.position - model.pantograph_offset)
    if distance == 0.0:
        return 0.0
    if speed <= 0.0:  # standing short of a section: it comes no nearer
        return math.inf
    periods = distance / (speed * model.period) - (len(state.pending) + 1)
    if periods <= 0.0:
        return 0.0
    return max_change * periods if max_change > 0.0 else math.inf


@jitable
def nominal_advance(model: NominalModel, state: NominalState, command: float, speed: float,
                    actuator: Actuator) -> tuple[float, NominalState]:
    """The period that starts now, `command` just sent and `speed` just measured: (the
    mean force the train will apply over it, N/kN; the model's state after it);
    `actuator` as for nominal_act."""
    pending, oldest = state.pending, state.oldest
    if len(pending):
        command, pending[oldest] = pending[oldest], command
        oldest = (oldest + 1) % len(pending)
    lag_state, mean = nominal_act(model, state.lag_state, command, speed, state.position,
                                  actuator)
    return mean, NominalState(lag_state, state.position + model.period * speed, pending, oldest)


@jitable
def known_resistance(model: NominalModel, speed: float, position: float,
                     basic_scale: float) -> float:
    """Basic resistance times `basic_scale` (the real over the nominal, as estimated on
    board; 1: the nominal's) plus line resistance at `speed` and `position`, N/kN."""
    train = model.train
    resistance = basic_scale * basic_resistance(speed, train.davis_a, train.davis_b,
                                                train.davis_c)
    if model.on_line:
        resistance += belt_resistance(model.line, position, train.length)
    return resistance


class Prediction(NamedTuple):
    speed: float      # m/s, `steps` periods from now
    travelled: float  # m, on the way there


@jitable
def nominal_predict(model: NominalModel, state: NominalState, speed: float,
                    unexplained: float, gain: float, steps: int, held: float,
                    resisted: bool, basic_scale: float, actuator: Actuator) -> Prediction:
    """The speed `steps` periods from now, from `speed` now, and the distance covered
    till then: the commands inside the dead time act in turn, then `held`; acceleration
    gain (force - known resistance) + `unexplained` (m/s^2, an observer's estimate of the
    rest; without `resisted` it holds the resistance too, and the model's is left out;
    `basic_scale` as for known_resistance, `actuator` as for nominal_act)."""
    h, lag_state, position = model.period, state.lag_state, state.position
    pending = state.pending
    travelled = 0.0  # the trapezoid's, as a preview's trajectory is integrated
    for i in range(steps):
        command = pending[(state.oldest + i) % len(pending)] if i < len(pending) else held
        lag_state, mean = nominal_act(model, lag_state, command, speed, position,
                                      actuator)
        if resisted:
            mean -= known_resistance(model, speed, position, basic_scale)
        acceleration = gain * mean + unexplained
        position += h * speed  # where the gradient is read: metres do not matter
        travelled += h * (speed + 0.5 * h * acceleration)
        speed += h * acceleration
    return Prediction(speed, travelled)
