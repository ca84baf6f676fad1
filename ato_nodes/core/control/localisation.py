"""On-board localisation: where the train is and how fast it goes, from its sensors
(core/train/odometry.py), ROS-free.

Two Kalman filters, each linear:
- the motion in the odometer's own frame, x = (d, w, a, j, c): the distance the odometer
  has counted (m), its speed (m/s), acceleration (m/s^2) and jerk (m/s^3), and the
  accelerometer's bias c (m/s^2). Each period h it predicts at constant jerk (d += w h +
  a h^2 / 2 + j h^3 / 6, w += a h + j h^2 / 2, a += j h), j a random walk
  (localisation.jerk_sigma per sqrt(s)) and a one too (localisation.acceleration_sigma):
  at constant acceleration the speed lags a train easing its braking into a stop, where
  neither the radar (too slow) nor the tachometer (under a pulse a period) reads it, and
  the train stops past its mark. A train whose tachometer has given no pulse for
  localisation.standstill_time while no traction is asked stands: its speed, acceleration
  and jerk are held at zero and its distance still (the profile's berth waits for a train
  that does not move at all), until a pulse comes or traction is asked. It takes the
  accelerometer's reading (a + c, its stated noise; c's prior its stated bias: the
  tachometer finds it while the wheels roll, so the filter coasts true through a slide),
  and the tachometer's count: its pulses since departure times the nominal pulse length
  is d (its quantisation's variance: a count's error does not add up along the run); the
  accelerometer's reading turned into the odometer's frame by the scale estimate;
- the map, m = (b, e): where the train is, s = b + d (1 - e), e the odometer's scale
  error (the tachometer reads 1 + e times the true speed: a wheel off its nominal
  diameter), a random walk (localisation.scale_drift); the radar's speed (the true speed,
  its stated noise) updates it, h = (0, -w) (while the count is set aside for a slip or
  a slide, the radar's speed is the motion's speed reading instead: the count then says
  nothing of the scale, and the filter coasts on the radar, not on a slipping wheel), and
  a mark read (a balise, a beacon),
  h = (1, -d), its variance the mark's stated accuracy's plus the counted
  distance's (whose error the map then holds: the distance's variance starts again from
  0). With neither radar nor marks e keeps its prior mean: the odometer alone cannot tell
  its scale (a filter of speed and scale together lets e drift with every reading).

Each update is by one scalar reading, written out (no LAPACK): Python and compiled code
give the same bits. A count more than localisation.gate sigmas off the prediction, or
(with the radar) an odometer speed more than localisation.gate sigmas off the radar's,
is a slip (above) or a slide (below): the radar's check catches a slip that starts with
the train, which a filter free to change its jerk would otherwise follow (its scale
estimate taking the creep; a contaminated-rail train then overran by 51 m, its slips
unseen). The count is set aside, the filter coasting on
the other sensors for at most localisation.slide_hold periods in a row; then the count
starts again from the filter's distance (the distance a slide lost is not counted
again), and is taken. The
position's sigma is recorded (position_sigma); the over- and under-reading amounts ETCS
states (L_DOUBTOVER, L_DOUBTUNDER) are, here, a multiple of it, the same both ways. A
mark's correction reaches the located position at localisation.correction_rate at most
(a position-indexed target would jump with it), what is still to come added to its sigma.

What the rail gives: a count set aside for ADHESION_READ s in a row is a slip or a slide
the protection is holding, the train then moving at what the rail gives times the
protection's efficiency. The force that takes (the filter's acceleration over xi, plus
the running resistance), over the train's figures (settings.slip_force, slide_force: N/kN
per unit of mu at its motored or braked share), is the adhesion coefficient the rail
has, and over Curtius-Kniffler's curve at the speed (core/train/adhesion.py) the
condition's factor. It is read while the count runs away from the filter's distance by
SLIP_CREEP of the distance run at least and the force asked (the drive's and the brakes'
own, which the train knows) exceeds the rail's by SLIP_EXCESS and SLIP_EXCESS_FORCE; the
largest over a slip or slide is what the rail gave (the count stays set aside a while
after the wheels roll again, the train then asking less); adhesion_seen keeps the lowest
over the slips and slides (NaN: none). It needs the accelerometer or the radar (the
slipping count says nothing of the train's acceleration).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from ..base.spec import param
from ..train.adhesion import adhesion_coefficient

LOCALISATION_PARAMETERS = (
    param("localisation.acceleration_sigma", 0.1, "the acceleration's random walk beside "
          "the jerk's, 1 sigma, m/s^2 per sqrt(s)", "plant", 0.0, 10.0),
    param("localisation.jerk_sigma", 1.7, "how fast the train's jerk may change, 1 sigma, "
          "m/s^3 per sqrt(s) (the filter's jerk a random walk)", "plant", 0.001, 100.0),
    param("localisation.scale_drift", 1e-5, "the odometer scale error's random walk, 1 sigma "
          "per sqrt(s)", "plant", 0.0, 1.0),
    param("localisation.gate", 4.0, "a tachometer reading this many sigmas off the "
          "prediction is a slip or a slide, set aside", "plant", 1.0, 100.0),
    param("localisation.correction_rate", 1.0, "the fastest the located position takes a "
          "mark's correction, m/s: a jump in position is a jump in a position-indexed target",
          "plant", 0.01, 1e3),
    param("localisation.standstill_time", 0.5, "no tachometer pulse this long while no "
          "traction is asked: the train stands, its located speed held at zero and its "
          "position still, s", "plant", 0.01, 60.0),
    param("localisation.slide_hold", 3.0, "the longest a slipping or sliding tachometer is "
          "set aside, s (then taken again)", "plant", 0.0, 60.0),
)


ADHESION_READ = 0.3  # s a count is set aside before the train's acceleration says the adhesion
SLIP_CREEP = 0.05  # the least creep of the wheels (over the distance run) that does: a count
                   # set aside at a sharp change of acceleration drifts back, not away, and
                   # one on an odometer scale 1-2 % off runs away slowly (at 2 % it read a
                   # rolling train for 0.08 of dry); a protection holds 10-20 %
SLIP_EXCESS = 0.1  # and the least share by which the force asked exceeds the rail's: a
SLIP_EXCESS_FORCE = 3.0  # and N/kN: a slipping or sliding wheel gives less than it is asked


class LocaliserSettings(NamedTuple):
    period: float               # s
    acceleration_drift: float   # variance added to a per period, (m/s^2)^2
    jerk_drift: float           # variance added to j per period, (m/s^3)^2
    scale_drift: float          # variance added to e per period
    count_variance: float       # m^2, the tachometer's count's quantisation
    radar_noise: float          # relative, 1 sigma
    accelerometer_noise: float  # (m/s^2)^2, its variance per reading
    gate: float                 # sigmas
    slide_hold: int             # periods
    correction_step: float      # m: the most of a correction the output takes a period
    xi: float                   # m/s^2 per N/kN
    slip_force: float           # N/kN per unit of mu while the wheels slip (traction)
    slide_force: float          # N/kN per unit of mu while they slide (braking)
    adhesion_read: int          # periods set aside before the acceleration says the adhesion
    standstill: int             # periods without a pulse, no traction asked: it stands


class LocaliserState(NamedTuple):
    motion: tuple               # (d, w, a, j, c): m, m/s, m/s^2, m/s^3 as the odometer
                                # counts them, and the accelerometer's bias c, m/s^2
    motion_covariance: np.ndarray  # 5 x 5
    map: tuple                  # (b, e): the position is b + d (1 - e)
    map_covariance: tuple       # (bb, be, ee)
    set_aside: int              # tachometer readings set aside in a row
    slide: float                # -1 sliding, +1 slipping, 0 rolling, as detected
    pending: float              # m of the marks' corrections the output has yet to take
    count_offset: float         # m the count has lost (or gained) to slides (slips)
    adhesion_seen: float        # the lowest adhesion factor slips and slides showed (NaN: none)
    slip_peak: float            # the largest factor the slip or slide under way showed (0: none)
    slip_start: tuple           # (the count's lead over the filter's distance, that
                                # distance) at its start, m
    last_count: float           # m, the tachometer's count the period before
    quiet: int                  # periods since the count last changed


MOTION = 5  # the motion filter's states


def localiser_settings(values, period: float, pulse_length: float, xi: float
                       ) -> LocaliserSettings:
    """The filter from the run's values: the sensors' stated magnitudes (odometry.*), its
    own (localisation.*) and the train's figures (its adhesive weights, its protection's
    efficiency, xi: m/s^2 per N/kN)."""
    acceleration = values["localisation.acceleration_sigma"]
    jerk = values["localisation.jerk_sigma"]
    per_mu = 1000.0 * values["plant.wsp_efficiency"]
    return LocaliserSettings(
        float(period), acceleration * acceleration * period, jerk * jerk * period,
        values["localisation.scale_drift"] ** 2 * period,
        pulse_length ** 2 / 12.0,  # a whole count of a distance run
        float(values["odometry.radar_noise"]), values["odometry.accelerometer_noise"] ** 2,
        float(values["localisation.gate"]), round(values["localisation.slide_hold"] / period),
        values["localisation.correction_rate"] * period,
        xi, per_mu * values["plant.motored_share"], per_mu * values["plant.braked_share"],
        max(1, round(ADHESION_READ / period)),
        max(1, round(values["localisation.standstill_time"] / period)))


def localiser_start(values, position: float, speed: float) -> LocaliserState:
    """A train departing at `position` and `speed`, known to a beacon's accuracy (it
    stands at a stop), its odometer to the wheel's stated diameter error, its
    accelerometer's bias to the stated one."""
    return LocaliserState((0.0, float(speed), 0.0, 0.0, 0.0),
                          np.diag([0.0, 1e-4, 1e-2, 1e-2,
                                   values["odometry.accelerometer_bias"] ** 2]),
                          (float(position), 0.0),
                          (values["odometry.beacon_accuracy"] ** 2, 0.0,
                           values["odometry.wheel_diameter_error"] ** 2), 0, 0.0, 0.0, 0.0,
                          math.nan, 0.0, (0.0, 0.0), 0.0, 0)


@jitable(inline=True)
def _row_by_column(row: tuple, p: np.ndarray, k: int) -> float:
    """sum_m row[m] p[m, k], summed from m = 0."""
    return 0.0 + row[0] * p[0, k] + row[1] * p[1, k] + row[2] * p[2, k] + row[3] * p[3, k] \
        + row[4] * p[4, k]


@jitable(inline=True)
def _dot(a: tuple, b: tuple) -> float:
    """sum_m a[m] b[m], summed from m = 0."""
    return 0.0 + a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4]


@jitable
def _predicted(settings: LocaliserSettings, state: LocaliserState
               ) -> tuple[tuple, np.ndarray]:
    """The motion and its covariance a period on, at constant jerk."""
    h = settings.period
    d, w, a, j, c = state.motion
    p = state.motion_covariance
    f = ((1.0, h, 0.5 * h * h, h * h * h / 6.0, 0.0), (0.0, 1.0, h, 0.5 * h * h, 0.0),
         (0.0, 0.0, 1.0, h, 0.0), (0.0, 0.0, 0.0, 1.0, 0.0), (0.0, 0.0, 0.0, 0.0, 1.0))
    covariance = np.empty((MOTION, MOTION))
    for i in range(MOTION):  # F P F', a row of F P at a time (no array for it)
        row = f[i]
        fp = (_row_by_column(row, p, 0), _row_by_column(row, p, 1), _row_by_column(row, p, 2),
              _row_by_column(row, p, 3), _row_by_column(row, p, 4))
        for k in range(i, MOTION):
            total = _dot(fp, f[k])
            covariance[i, k] = total
            covariance[k, i] = total
    covariance[2, 2] += settings.acceleration_drift
    covariance[3, 3] += settings.jerk_drift
    return (d + h * w + 0.5 * h * h * a + h * h * h / 6.0 * j, w + h * a + 0.5 * h * h * j,
            a + h * j, j, c), covariance


@jitable
def _updated(x: tuple, p: np.ndarray, h: tuple, reading: float, variance: float,
             gate: float) -> tuple[tuple, bool]:
    """The motion's update by one scalar reading with measurement row `h`, `p` updated in
    place; (motion, taken): a reading past `gate` sigmas (gate > 0) is not taken."""
    ph = (_row_by_column(h, p, 0), _row_by_column(h, p, 1), _row_by_column(h, p, 2),
          _row_by_column(h, p, 3), _row_by_column(h, p, 4))  # P h' (P symmetric)
    innovation_variance = variance
    predicted = 0.0
    for m in range(MOTION):
        innovation_variance += h[m] * ph[m]
        predicted += h[m] * x[m]
    innovation = reading - predicted
    if gate > 0.0 and innovation * innovation > gate * gate * innovation_variance:
        return x, False
    for i in range(MOTION):
        for k in range(i, MOTION):  # the upper triangle, mirrored: symmetric to the bit
            p[i, k] = p[i, k] - ph[i] * ph[k] / innovation_variance
            p[k, i] = p[i, k]
    step = innovation / innovation_variance
    return (x[0] + ph[0] * step, x[1] + ph[1] * step, x[2] + ph[2] * step,
            x[3] + ph[3] * step, x[4] + ph[4] * step), True


@jitable
def _map_updated(mapped: tuple, covariance: tuple, h: tuple, innovation: float,
                 variance: float) -> tuple[tuple, tuple]:
    """The map's update by one scalar reading with measurement row `h` (by b, e)."""
    bb, be, ee = covariance
    pb, pe = bb * h[0] + be * h[1], be * h[0] + ee * h[1]  # P h'
    innovation_variance = h[0] * pb + h[1] * pe + variance
    step = innovation / innovation_variance
    return ((mapped[0] + pb * step, mapped[1] + pe * step),
            (bb - pb * pb / innovation_variance, be - pb * pe / innovation_variance,
             ee - pe * pe / innovation_variance))


@jitable
def _mapped(settings: LocaliserSettings, state: LocaliserState, x: tuple, p: np.ndarray,
            radar_speed: float, mark_reading: float, mark_variance: float
            ) -> tuple[tuple, tuple]:
    """The map a period on (e's drift), then the radar's speed (the true speed, against
    the odometer's w (1 - e): it finds e) and a mark's position (against b + d (1 - e)),
    NaN: none."""
    d, w = x[0], x[1]
    b, e = state.map
    bb, be, ee = state.map_covariance
    # e's drift changes the distance still to come, not the one counted: b moves with it
    q = settings.scale_drift
    mapped, covariance = (b, e), (bb + d * d * q, be + d * q, ee + q)
    if radar_speed == radar_speed:
        noise = settings.radar_noise * radar_speed
        mapped, covariance = _map_updated(
            mapped, covariance, (0.0, -w), radar_speed - w * (1.0 - mapped[1]),
            noise * noise + (1.0 - mapped[1]) ** 2 * p[1, 1])
    if mark_reading == mark_reading:
        mapped, covariance = _map_updated(
            mapped, covariance, (1.0, -d), mark_reading - (mapped[0] + d * (1.0 - mapped[1])),
            mark_variance + (1.0 - mapped[1]) ** 2 * p[0, 0])
    return mapped, covariance


@jitable
def _radar_disagrees(settings: LocaliserSettings, state: LocaliserState, x: tuple,
                     p: np.ndarray, radar_speed: float) -> float:
    """+1 when the odometer's speed (on the scale's estimate) runs past the radar's by
    more than localisation.gate sigmas (a slip), -1 under it (a slide), 0 otherwise or
    without a reading: a slip that starts as the train does grows with its speed, and a
    filter free to change its acceleration follows the count."""
    if radar_speed != radar_speed:
        return 0.0
    e, ee = state.map[1], state.map_covariance[2]
    noise = settings.radar_noise * radar_speed
    variance = noise * noise + (1.0 - e) ** 2 * p[1, 1] + x[1] * x[1] * ee
    lead = x[1] * (1.0 - e) - radar_speed
    if lead * lead <= settings.gate * settings.gate * variance:
        return 0.0
    return 1.0 if lead > 0.0 else -1.0


@jitable
def _adhesion_read(settings: LocaliserSettings, state: LocaliserState, x: tuple,
                   lead: float, set_aside: int, slide: float, resistance: float,
                   demand: float) -> tuple[float, float, tuple]:
    """(adhesion_seen, slip_peak, slip_start) after a period whose count leads the
    filter's distance by `lead` (m) and was set aside `set_aside` times in a row."""
    adhesion_seen, slip_peak, slip_start = state.adhesion_seen, 0.0, (lead, x[0])
    if set_aside > 1:
        slip_peak, slip_start = state.slip_peak, state.slip_start
        run = x[0] - slip_start[1]
        if slide * (lead - slip_start[0]) > SLIP_CREEP * run > 0.0:
            # the wheels creeping: the rail's factor as the train moves the way they try to
            per_mu = settings.slip_force if slide > 0.0 else settings.slide_force
            rail = x[2] / settings.xi + resistance  # N/kN the rail gives
            excess = slide * (demand - rail)  # asked more than given, by this much
            if excess > max(SLIP_EXCESS * slide * rail, SLIP_EXCESS_FORCE):
                slip_peak = max(slip_peak, slide * rail / (
                    per_mu * adhesion_coefficient(x[1] * (1.0 - state.map[1]), 1.0)))
    elif state.set_aside >= settings.adhesion_read and state.slip_peak > 0.0 and not (
            state.slip_peak >= adhesion_seen):  # a slip or slide over: the lowest (NaN: none)
        adhesion_seen = state.slip_peak
    return adhesion_seen, slip_peak, slip_start


@jitable
def localiser_step(settings: LocaliserSettings, state: LocaliserState, counted: float,
                   radar_speed: float, acceleration: float, mark_reading: float,
                   mark_sigma: float, resistance: float, demand: float) -> LocaliserState:
    """One period: the prediction, then the readings of its end (NaN: none); `counted`
    the tachometer's pulses since departure times the nominal pulse length, m;
    `resistance` the train's running resistance (basic and the line's), `demand` the
    force its drive and brakes ask, N/kN."""
    x, p = _predicted(settings, state)
    frame = 1.0 / (1.0 - state.map[1])  # a true speed in the odometer's frame
    if acceleration == acceleration:  # it reads the acceleration plus its bias
        x, _ = _updated(x, p, (0.0, 0.0, 1.0, 0.0, 1.0), acceleration * frame,
                        settings.accelerometer_noise, 0.0)
    set_aside, slide, count_offset = 0, 0.0, state.count_offset
    reading = counted - count_offset
    if state.set_aside >= settings.slide_hold:  # the count starts again from the filter's
        count_offset = counted - x[0]
    else:
        slide = _radar_disagrees(settings, state, x, p, radar_speed)
        if slide == 0.0:
            x, taken = _updated(x, p, (1.0, 0.0, 0.0, 0.0, 0.0), reading,
                                settings.count_variance, settings.gate)
            if not taken:
                slide = 1.0 if reading > x[0] else -1.0
        if slide != 0.0:
            set_aside = state.set_aside + 1
    adhesion_seen, slip_peak, slip_start = _adhesion_read(
        settings, state, x, reading - x[0], set_aside, slide, resistance, demand)
    if (set_aside > 0 or state.set_aside > 0) and radar_speed == radar_speed:
        # a slip or slide: the radar's speed is the train's, not a word on the scale
        noise = settings.radar_noise * radar_speed
        x, _ = _updated(x, p, (0.0, 1.0, 0.0, 0.0, 0.0), radar_speed * frame, noise * noise, 0.0)
        radar_speed = math.nan
    mapped, map_covariance = _mapped(settings, state, x, p, radar_speed, mark_reading,
                                     mark_sigma * mark_sigma)
    quiet = state.quiet + 1 if counted == state.last_count else 0
    if quiet >= settings.standstill and demand <= 0.0:  # it stands: nothing moves
        x = (state.motion[0], 0.0, 0.0, 0.0, state.motion[4])
    if mark_reading == mark_reading:  # the counted distance's error is the map's now
        for i in range(MOTION):
            p[0, i], p[i, 0] = 0.0, 0.0
    # the estimate's move beyond the distance counted: taken by the output at a bounded rate
    before = state.map[0] + state.motion[0] * (1.0 - state.map[1])
    moved = (x[0] - state.motion[0]) * (1.0 - mapped[1])
    pending = state.pending + mapped[0] + x[0] * (1.0 - mapped[1]) - before - moved
    pending -= min(max(pending, -settings.correction_step), settings.correction_step)
    return LocaliserState(x, p, mapped, map_covariance, set_aside, slide, pending,
                          count_offset, adhesion_seen, slip_peak, slip_start, counted, quiet)


@jitable
def located_estimate(state: LocaliserState) -> tuple[float, float, float, float]:
    """(position m, speed m/s, the position's sigma m, the odometer's scale error e): the
    position with the corrections it has yet to take, their size added to its sigma."""
    d, w, _, _, _ = state.motion
    b, e = state.map
    bb, be, ee = state.map_covariance
    variance = (bb - 2.0 * d * be + d * d * ee
                + (1.0 - e) ** 2 * state.motion_covariance[0, 0])
    return (b + d * (1.0 - e) - state.pending, w * (1.0 - e),
            math.sqrt(max(variance, 0.0)) + abs(state.pending), e)
