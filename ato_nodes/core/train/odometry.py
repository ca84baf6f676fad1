"""The train's position and speed sensors, as the real train reads them, ROS-free: wheel
tachometers, a Doppler radar, an accelerometer, and the balises and platform beacons it
passes (docs/localisation.md: the error magnitudes and their sources).

- Tachometer: pulses of the wheel's turning, odometry.pulses_per_revolution per turn of
  a wheel whose real diameter is the nominal odometry.wheel_diameter times (1 + a draw
  of odometry.wheel_diameter_error), counted whole. The wheel rolls the train's distance
  times (1 + its creep): 0 while it rolls, the protection's creep while it slips or
  slides (core/train/adhesion.py). Its speed reading is the pulses of the last period
  times the nominal pulse length, over the period.
- Radar: the true speed times (1 + odometry.radar_noise times a normal draw), none below
  RADAR_FLOOR (a Doppler radar sees no speed at a standstill).
- Accelerometer: the true acceleration plus a bias drawn once per run (odometry.
  accelerometer_bias, 1 sigma) plus odometry.accelerometer_noise times a draw per step.
- Marks: balises every odometry.balise_spacing from the start, and beacons
  odometry.beacon_distances before each stop (the line's stations, or its end). Each is
  laid where the ATO's map says plus a draw of its stated accuracy (odometry.
  balise_accuracy, odometry.beacon_accuracy): passing it, the train reads its map position
  plus the distance run since, that is its true position less the mark's error.

Each sensor draws from its own stream of odometry.seed (SENSOR_STREAMS): adding a sensor
never shifts another's draws.
"""

from __future__ import annotations

import math
import re
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from ..base.spec import TextForm, param
from .line import Line

RADAR_FLOOR = 0.3  # m/s: below it the radar reads nothing (NaN)
# Each sensor's own stream of odometry.seed: numpy's SeedSequence of (seed, this index)
SENSOR_STREAMS = {"wheel": 1, "radar": 2, "accelerometer": 3, "balises": 4, "beacons": 5}
_DISTANCE = r"\s*\d+(?:\.\d*)?\s*"
DISTANCES_FORM = TextForm(rf"\s*|{_DISTANCE}(?:,{_DISTANCE})*",
                          "distances in m, comma-separated, e.g. '20, 5' ('' = none)")

PARAMETERS = (
    param("odometry.enabled", False, "the ATO knows its position and speed only from its "
          "sensors (tachometer, radar, accelerometer, balises, beacons) through the on-board "
          "localisation (false: it reads the true position and the speed sensor, the papers' "
          "setting)", ("plant", "profile", "recorder")),
    param("odometry.seed", 0, "seed of the sensors' errors (each sensor its own stream)",
          "plant", 0, 2**31 - 1),
    param("odometry.wheel_diameter", 0.84, "the measured wheel's nominal diameter, m", "plant",
          0.1, 3.0),
    param("odometry.wheel_diameter_error", 0.005, "its real diameter's relative error, 1 "
          "sigma (drawn per run; the localisation's prior on the odometer's scale)", "plant",
          0.0, 0.1),
    param("odometry.pulses_per_revolution", 200, "the tachometer's pulses per wheel turn",
          "plant", 1, 100000),
    param("odometry.radar", False, "a Doppler radar measures the speed over ground", "plant"),
    param("odometry.radar_noise", 0.01, "the radar's relative error per reading, 1 sigma",
          "plant", 0.0, 0.5),
    param("odometry.accelerometer", False, "an accelerometer measures the acceleration",
          "plant"),
    param("odometry.accelerometer_bias", 0.02, "the accelerometer's bias, 1 sigma (drawn per "
          "run), m/s^2", "plant", 0.0, 1.0),
    param("odometry.accelerometer_noise", 0.02, "the accelerometer's noise per reading, 1 "
          "sigma, m/s^2", "plant", 0.0, 1.0),
    param("odometry.balise_spacing", 0.0, "a balise group every this many m from the "
          "departure (0 = none)", "plant", 0.0, 1e6),
    param("odometry.balise_accuracy", 1.0, "a balise's location accuracy, 1 sigma, m",
          "plant", 0.0, 100.0),
    param("odometry.beacon_distances", "", "the stopping-point beacons before each stop, m "
          "before its mark ('' = none)", "plant", form=DISTANCES_FORM),
    param("odometry.beacon_accuracy", 0.05, "a beacon's location accuracy, 1 sigma, m (also "
          "the departure position's)", "plant", 0.0, 10.0),
)


class OdometrySettings(NamedTuple):
    """The sensors of a run (the plant's: the true errors drawn)."""

    period: float              # s
    pulse_length: float        # m, the nominal wheel's circumference over its pulses
    wheel_scale: float         # the real wheel's diameter over the nominal
    radar: bool
    radar_noise: float         # relative, 1 sigma
    accelerometer: bool
    accelerometer_bias: float  # m/s^2, this run's
    accelerometer_noise: float  # m/s^2, 1 sigma
    draws: np.ndarray          # steps x 2: the radar's and the accelerometer's normal draws
    marks: np.ndarray          # m, where the ATO's map has each balise and beacon, ascending
    mark_errors: np.ndarray    # m, where each lies less where the map has it
    mark_sigmas: np.ndarray    # m, each one's stated accuracy, 1 sigma


class OdometerState(NamedTuple):
    """What the sensors carry from one step to the next."""

    wheel_distance: float      # m the wheel's tread has rolled
    pulses: float              # counted, whole
    tacho_speed: float         # m/s, the last period's reading
    next_mark: int             # the first mark not passed
    mark_reading: float        # m, the position read at the mark passed in the last period
    mark_sigma: float          # m, its stated accuracy (NaN: no mark passed)


def odometry_settings(values, period: float, steps: int, line: Line | None,
                      start: float) -> OdometrySettings:
    """The run's sensors from its odometry.* values, their errors drawn, for `steps` steps
    of a train departing from `start` (m) on `line`."""
    wheel = sensor_stream(values, "wheel").standard_normal()
    wheel_scale = 1.0 + values["odometry.wheel_diameter_error"] * wheel
    draws = np.zeros((steps, 2))
    if values["odometry.radar"]:
        draws[:, 0] = sensor_stream(values, "radar").standard_normal(steps)
    bias = 0.0
    if values["odometry.accelerometer"]:
        accelerometer = sensor_stream(values, "accelerometer")
        bias = values["odometry.accelerometer_bias"] * accelerometer.standard_normal()
        draws[:, 1] = accelerometer.standard_normal(steps)
    marks = _marks(values, line, start)
    return OdometrySettings(
        float(period), math.pi * values["odometry.wheel_diameter"]
        / values["odometry.pulses_per_revolution"], float(wheel_scale),
        bool(values["odometry.radar"]), float(values["odometry.radar_noise"]),
        bool(values["odometry.accelerometer"]), float(bias),
        float(values["odometry.accelerometer_noise"]), draws, *marks)


def sensor_stream(values, name: str) -> np.random.Generator:
    """Sensor `name`'s own stream of odometry.seed (SENSOR_STREAMS)."""
    return np.random.default_rng([values["odometry.seed"], SENSOR_STREAMS[name]])


def _marks(values, line: Line | None, start: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions, errors, sigmas) of the balises and beacons ahead of `start`, ascending."""
    end = line.length if line is not None else start
    spacing = values["odometry.balise_spacing"]
    balises = np.arange(start + spacing, end, spacing) if spacing > 0.0 else np.zeros(0)
    stops = [station.position for station in line.stations] if line is not None else []
    stops = stops or ([line.stop_position] if line is not None else [])
    distances = beacon_distances(values["odometry.beacon_distances"])
    beacons = np.array(sorted({stop - distance for stop in stops for distance in distances
                               if stop - distance > start}))
    balise_errors = values["odometry.balise_accuracy"] * sensor_stream(
        values, "balises").standard_normal(len(balises))
    beacon_errors = values["odometry.beacon_accuracy"] * sensor_stream(
        values, "beacons").standard_normal(len(beacons))
    positions = np.concatenate([balises, beacons])
    order = np.argsort(positions, kind="stable")
    sigmas = np.concatenate([np.full(len(balises), values["odometry.balise_accuracy"]),
                             np.full(len(beacons), values["odometry.beacon_accuracy"])])
    return (positions[order], np.concatenate([balise_errors, beacon_errors])[order],
            sigmas[order])


def beacon_distances(text: str) -> tuple[float, ...]:
    """odometry.beacon_distances' numbers, m before each stop ('' = none)."""
    return tuple(float(part) for part in re.split(r"\s*,\s*", text.strip()) if part)


def odometer_start(speed: float) -> OdometerState:
    """The sensors of a train departing at `speed`: nothing counted, no mark passed."""
    return OdometerState(0.0, 0.0, speed, 0, math.nan, math.nan)


@jitable
def odometer_advance(settings: OdometrySettings, state: OdometerState, start: float,
                     end: float, creep: float) -> OdometerState:
    """The sensors over a period the train ran from `start` to `end` (m, true) with its
    wheels at `creep`: the pulses counted, the tachometer's reading, a mark passed."""
    wheel_distance = state.wheel_distance + (end - start) * (1.0 + creep)
    pulses = float(math.floor(wheel_distance / (settings.pulse_length * settings.wheel_scale)))
    tacho_speed = (pulses - state.pulses) * settings.pulse_length / settings.period
    next_mark, reading, sigma = state.next_mark, math.nan, math.nan
    marks = settings.marks
    while next_mark < len(marks) and end >= marks[next_mark] + settings.mark_errors[next_mark]:
        reading = end - settings.mark_errors[next_mark]
        sigma = settings.mark_sigmas[next_mark]
        next_mark += 1
    return OdometerState(wheel_distance, pulses, tacho_speed, next_mark, reading, sigma)


@jitable
def radar_reading(settings: OdometrySettings, k: int, speed: float) -> float:
    """The radar's speed at step k (NaN: none fitted, or too slow to read)."""
    if not settings.radar or abs(speed) < RADAR_FLOOR:
        return math.nan
    return speed * (1.0 + settings.radar_noise * settings.draws[k, 0])


@jitable
def accelerometer_reading(settings: OdometrySettings, k: int, acceleration: float) -> float:
    """The accelerometer's reading at step k (NaN: none fitted)."""
    if not settings.accelerometer:
        return math.nan
    return (acceleration + settings.accelerometer_bias
            + settings.accelerometer_noise * settings.draws[k, 1])
