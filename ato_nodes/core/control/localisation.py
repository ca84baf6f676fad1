"""On-board localisation: where the train is and how fast it goes, from its sensors
(core/train/odometry.py), ROS-free.

A Kalman filter on x = (s, v, a, e): position (m), speed (m/s), acceleration (m/s^2)
and the odometer's scale error e (the tachometer reads 1 + e times the speed: a wheel
whose real diameter is off the nominal reads 1 / (1 + error) of it). Each period h:

  predict   s += v h + a h^2 / 2,  v += a h,  a a random walk (localisation.
            acceleration_sigma, per sqrt(s): the train's jerk), e a random walk
            (localisation.scale_drift)
  update    the tachometer: the pulses of the period over it, the mean speed over the
            period (h(x) = (v - a h / 2) (1 + e), its pulse quantisation's variance); the
            radar's speed (its stated noise); the accelerometer's (its noise and bias); a
            mark's position (its stated accuracy)

each update by one scalar reading, written out (no LAPACK): Python and compiled code
give the same bits. The tachometer cannot tell the speed from its own scale error: its
update leaves e as it is (e a consider state, Schmidt's), which the marks alone move
(through the correlations the tachometer's updates build); else e drifts between marks.
A tachometer reading more than localisation.gate sigmas off the prediction is a slip
(above) or a slide (below): it is set aside, the filter coasting on the other sensors,
for at most localisation.slide_hold periods in a row (then taken again: a train with the
tachometer alone must not coast for ever). The position's sigma is recorded
(position_sigma); the over- and under-reading amounts ETCS states (L_DOUBTOVER,
L_DOUBTUNDER) are, here, a multiple of it, the same both ways.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from ..base.spec import param

LOCALISATION_PARAMETERS = (
    param("localisation.acceleration_sigma", 0.5, "how fast the train's acceleration may "
          "change, 1 sigma, m/s^2 per sqrt(s) (the filter's acceleration a random walk)",
          "plant", 0.001, 10.0),
    param("localisation.scale_drift", 1e-5, "the odometer scale error's random walk, 1 sigma "
          "per sqrt(s)", "plant", 0.0, 1.0),
    param("localisation.gate", 4.0, "a tachometer reading this many sigmas off the "
          "prediction is a slip or a slide, set aside", "plant", 1.0, 100.0),
    param("localisation.slide_hold", 3.0, "the longest a slipping or sliding tachometer is "
          "set aside, s (then taken again)", "plant", 0.0, 60.0),
)


class LocaliserSettings(NamedTuple):
    period: float               # s
    acceleration_drift: float   # variance added to a per period, (m/s^2)^2
    scale_drift: float          # variance added to e per period
    tacho_variance: float       # (m/s)^2, the tachometer's quantisation
    radar_noise: float          # relative, 1 sigma
    accelerometer_variance: float  # (m/s^2)^2, its noise and bias
    gate: float                 # sigmas
    slide_hold: int             # periods


class LocaliserState(NamedTuple):
    estimate: tuple             # (s, v, a, e): m, m/s, m/s^2, 1
    covariance: np.ndarray      # 4 x 4
    set_aside: int              # tachometer readings set aside in a row
    slide: float                # -1 sliding, +1 slipping, 0 rolling, as detected


POSITION, SPEED, ACCELERATION, SCALE = range(4)


def localiser_settings(values, period: float, pulse_length: float) -> LocaliserSettings:
    """The filter from the run's values: the sensors' stated magnitudes (odometry.*) and
    its own (localisation.*)."""
    jerk = values["localisation.acceleration_sigma"]
    return LocaliserSettings(
        float(period), jerk * jerk * period, values["localisation.scale_drift"] ** 2 * period,
        (pulse_length / period) ** 2 / 6.0,  # a difference of two whole counts
        float(values["odometry.radar_noise"]),
        values["odometry.accelerometer_noise"] ** 2 + values["odometry.accelerometer_bias"] ** 2,
        float(values["localisation.gate"]), round(values["localisation.slide_hold"] / period))


def localiser_start(values, position: float, speed: float) -> LocaliserState:
    """A train departing at `position` and `speed`, known to a beacon's accuracy (it
    stands at a stop), its odometer to the wheel's stated diameter error."""
    covariance = np.diag([values["odometry.beacon_accuracy"] ** 2, 1e-4, 1e-2,
                          values["odometry.wheel_diameter_error"] ** 2])
    return LocaliserState((float(position), float(speed), 0.0, 0.0), covariance, 0, 0.0)


@jitable
def _predicted(settings: LocaliserSettings, state: LocaliserState
               ) -> tuple[tuple, np.ndarray]:
    """The estimate and covariance a period on: F = [[1, h, h^2/2, 0], [0, 1, h, 0],
    [0, 0, 1, 0], [0, 0, 0, 1]], written out."""
    h = settings.period
    s, v, a, e = state.estimate
    p = state.covariance
    f = np.zeros((4, 4))
    f[0, 0], f[0, 1], f[0, 2] = 1.0, h, 0.5 * h * h
    f[1, 1], f[1, 2], f[2, 2], f[3, 3] = 1.0, h, 1.0, 1.0
    fp = np.zeros((4, 4))
    for i in range(4):
        for j in range(4):
            fp[i, j] = f[i, 0] * p[0, j] + f[i, 1] * p[1, j] + f[i, 2] * p[2, j] + f[i, 3] * p[3, j]
    covariance = np.zeros((4, 4))
    for i in range(4):
        for j in range(i, 4):
            covariance[i, j] = (fp[i, 0] * f[j, 0] + fp[i, 1] * f[j, 1] + fp[i, 2] * f[j, 2]
                                + fp[i, 3] * f[j, 3])
            covariance[j, i] = covariance[i, j]
    covariance[ACCELERATION, ACCELERATION] += settings.acceleration_drift
    covariance[SCALE, SCALE] += settings.scale_drift
    return (s + h * v + 0.5 * h * h * a, v + h * a, a, e), covariance


@jitable
def _updated(estimate: tuple, p: np.ndarray, h: tuple, predicted: float, reading: float,
             variance: float, gate: float, considered: int = -1
             ) -> tuple[tuple, np.ndarray, bool]:
    """The update by one scalar reading with measurement row `h` (by s, v, a, e), in
    place of `p`; (estimate, covariance, taken): a reading past `gate` sigmas (gate > 0)
    is not taken. The state `considered` (Schmidt's consider state; -1: none) keeps its
    value and variance, its correlations updated."""
    ph = (p[0, 0] * h[0] + p[0, 1] * h[1] + p[0, 2] * h[2] + p[0, 3] * h[3],
          p[1, 0] * h[0] + p[1, 1] * h[1] + p[1, 2] * h[2] + p[1, 3] * h[3],
          p[2, 0] * h[0] + p[2, 1] * h[1] + p[2, 2] * h[2] + p[2, 3] * h[3],
          p[3, 0] * h[0] + p[3, 1] * h[1] + p[3, 2] * h[2] + p[3, 3] * h[3])  # P h'
    innovation_variance = h[0] * ph[0] + h[1] * ph[1] + h[2] * ph[2] + h[3] * ph[3] + variance
    innovation = reading - predicted
    if gate > 0.0 and innovation * innovation > gate * gate * innovation_variance:
        return estimate, p, False
    for i in range(4):
        for j in range(i, 4):  # the upper triangle, mirrored: symmetric to the bit
            if i != considered or j != considered:
                p[i, j] = p[i, j] - ph[i] * ph[j] / innovation_variance
                p[j, i] = p[i, j]
    step = innovation / innovation_variance
    x = (estimate[0] + ph[0] * step, estimate[1] + ph[1] * step,
         estimate[2] + ph[2] * step, estimate[3] + ph[3] * step)
    if considered == SCALE:
        x = (x[0], x[1], x[2], estimate[3])
    return x, p, True


@jitable
def localiser_step(settings: LocaliserSettings, state: LocaliserState, tacho_speed: float,
                   radar_speed: float, acceleration: float, mark_reading: float,
                   mark_sigma: float) -> LocaliserState:
    """One period: the prediction, then the readings of its end (NaN: none)."""
    x, p = _predicted(settings, state)
    if acceleration == acceleration:
        x, p, _ = _updated(x, p, (0.0, 0.0, 1.0, 0.0), x[ACCELERATION], acceleration,
                           settings.accelerometer_variance, 0.0)
    if radar_speed == radar_speed:
        noise = settings.radar_noise * radar_speed
        x, p, _ = _updated(x, p, (0.0, 1.0, 0.0, 0.0), x[SPEED], radar_speed, noise * noise,
                           0.0)
    gate = settings.gate if state.set_aside < settings.slide_hold else 0.0
    h = settings.period
    scale, mean_speed = 1.0 + x[SCALE], x[SPEED] - 0.5 * h * x[ACCELERATION]
    predicted = mean_speed * scale
    x, p, taken = _updated(x, p, (0.0, scale, -0.5 * h * scale, mean_speed), predicted,
                           tacho_speed, settings.tacho_variance, gate, SCALE)
    set_aside, slide = 0, 0.0
    if not taken:
        set_aside, slide = state.set_aside + 1, 1.0 if tacho_speed > predicted else -1.0
    if mark_reading == mark_reading:
        x, p, _ = _updated(x, p, (1.0, 0.0, 0.0, 0.0), x[POSITION], mark_reading,
                           mark_sigma * mark_sigma, 0.0)
    return LocaliserState(x, p, set_aside, slide)


@jitable
def position_sigma(state: LocaliserState) -> float:
    """The position's standard deviation, m."""
    return math.sqrt(max(state.covariance[POSITION, POSITION], 0.0))
