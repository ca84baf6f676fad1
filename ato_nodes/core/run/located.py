"""Where the ATO believes its train is: the train's sensors (core/train/odometry.py) read
and the on-board localisation (core/control/localisation.py) stepped, each step, by the
plant's stage and by the compiled loop alike (odometry.enabled; off, the ATO reads the
true position and the speed sensor, the papers' setting).

It runs with the plant, beside the train it measures (the odometry unit is on board):
no message hop is added to a step's critical path (plant -> controller -> plant); the
profile takes the located position and the controller the located speed, and the true
ones stay the plant's, for scoring.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from ..control.localisation import (LocaliserSettings, LocaliserState, localiser_settings,
                                    localiser_start, localiser_step, located_estimate)
from ..train.line import Line
from ..train.odometry import (OdometerState, OdometrySettings, accelerometer_reading,
                              odometer_advance, odometer_start, odometry_settings,
                              radar_reading)
from ..train.plant import TrainMotion, TrainParameters, TrainSettings, demand_and_creep, \
    train_outputs

# What a run with odometry records beside the SERIES, one value a step (docs/reference.md);
# its measured_speed is then the located speed, the controller's input
ODOMETRY_SERIES = ("located_position", "position_sigma", "scale_error", "tacho_speed",
                   "radar_speed", "acceleration_reading", "mark_reading", "slide_detected",
                   "wheel_creep", "adhesion_seen", "located_speed")


class Odometry(NamedTuple):
    """The sensors and the filter of a run (LoopInputs.odometry)."""

    sensors: OdometrySettings
    localiser: LocaliserSettings


class OdometryState(NamedTuple):
    odometer: OdometerState
    localiser: LocaliserState
    creep: float               # the wheels' creep over the last period (true)
    demand: float              # N/kN the drive and brakes ask at its end (the train knows)


def odometry_of(values, line: Line | None, steps: int
                ) -> tuple[Odometry | None, OdometryState | None]:
    """The run's odometry and its state at departure; (None, None) when off."""
    if not values["odometry.enabled"]:
        return None, None
    period, start = values["run.period"], values["plant.initial_position"]
    sensors = odometry_settings(values, period, steps, line, start)
    xi = TrainParameters.from_values(values).xi  # the nominal train's: what the ATO knows
    return (Odometry(sensors, localiser_settings(values, period, sensors.pulse_length, xi)),
            OdometryState(odometer_start(values["plant.initial_speed"]),
                          localiser_start(values, start, values["plant.initial_speed"]), 0.0,
                          0.0))


@jitable
def located(odometry: Odometry | None, state: OdometryState | None, k: int,
            train: TrainSettings, motion: TrainMotion, row: np.ndarray
            ) -> tuple[OdometryState | None, float, float]:
    """Step k's readings of the train in `motion` and the filter after them: (state,
    located position, located speed), row holding ODOMETRY_SERIES; (state, NaN, NaN) when
    off (state None)."""
    if state is None:
        return state, math.nan, math.nan
    sensors, odometer = odometry.sensors, state.odometer
    radar = radar_reading(sensors, k, motion.speed)
    acceleration, _, resistance, line_resistance = train_outputs(train, motion)
    measured_acceleration = accelerometer_reading(sensors, k, acceleration)
    localiser = state.localiser
    if k > 0:  # at k = 0 it stands where it departs
        localiser = localiser_step(odometry.localiser, localiser,
                                   odometer.pulses * sensors.pulse_length, radar,
                                   measured_acceleration, odometer.mark_reading,
                                   odometer.mark_sigma, resistance + line_resistance,
                                   state.demand)
    position, speed, sigma, scale_error = located_estimate(localiser)
    row[0], row[1], row[2] = position, sigma, scale_error
    row[3], row[4], row[5] = odometer.tacho_speed, radar, measured_acceleration
    row[6], row[7], row[8] = odometer.mark_reading, localiser.slide, state.creep
    row[9], row[10] = localiser.adhesion_seen, speed
    return OdometryState(odometer, localiser, state.creep, state.demand), position, speed


@jitable
def odometer_moved(odometry: Odometry | None, state: OdometryState | None,
                   train: TrainSettings, before: TrainMotion, after: TrainMotion
                   ) -> OdometryState | None:
    """The sensors after the train's period from `before` to `after`: the wheels at the
    creep of the force asked of the rail at its end (kept: the localisation's next step
    reads it)."""
    if state is None:
        return state
    demand, creep = demand_and_creep(train, after)
    return OdometryState(odometer_advance(odometry.sensors, state.odometer, before.position,
                                          after.position, creep), state.localiser, creep,
                         demand)


@jitable
def adhesion_seen(state: OdometryState | None) -> float:
    """The lowest adhesion factor the localisation has seen in slips and slides (NaN:
    none, or no odometry)."""
    if state is None:
        return math.nan
    return state.localiser.adhesion_seen
