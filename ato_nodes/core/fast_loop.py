"""The lockstep loop compiled (numba), for the runs that tuning repeats most.

simulate() hands a run here when numba is installed and the run is of the kind a
compiled loop covers: Han's ADRC (seed 000 and seed 003's NLADRC), a time-indexed
target without the stepped approach, the point-mass train on the open track
(no line) with no dead time; lag, envelopes and the noisy, quantised speed sensor
included. Everything else (lines, position-indexed curves, other controllers,
dead time, live gain changes) runs the Python loop. The step is the one
core/loop.py describes, in the same order, and every formula is the Python path's
own function (core.kernels: plant.rates, rk4_substep and sensor_reading,
adrc.han_adrc_step, limiter.limit_command, indices.running_add), compiled;
tests/test_fast_loop.py checks that both paths give the same bits.

The targets of a time-indexed plan do not depend on the run, so the horizons are
computed once per process and plan, by the ProfileStage itself, and reused by
every tuning candidate.
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np

from .adrc import HanADRC, han_adrc_step
from .indices import RunningIndex, running_add
from .kernels import AVAILABLE, compiled
from .schema import NodeValues
from .plant import (achievable, basic_resistance, disturbance, no_line, rates, rk4_substep,
                    sensor_reading)


def covers(profile, plant, controller, changes) -> bool:
    """Whether the compiled loop runs this run (stages built by simulate())."""
    train = plant.train
    return (AVAILABLE and not changes and type(controller.controller) is HanADRC
            and not profile.context.plan.position_indexed and profile.approach_step <= 0.0
            and getattr(profile.context.plan, "limit", None) is None
            and profile.context.line is None and train.line is None and not train.delayed)


@functools.lru_cache(maxsize=4)
def _horizons(profile_values: str) -> np.ndarray:
    from .loop import ProfileStage
    profile = ProfileStage(NodeValues("profile", json.loads(profile_values)))
    rows = []
    while len(rows) < profile.total_steps:
        rows.extend(profile.on_position(0.0))  # time-indexed: the position is not read
    return np.array(rows, dtype=float)


def horizons(profile) -> np.ndarray:
    """Every step's horizon (steps x (N + 1)) as a ProfileStage publishes them, computed
    once per process and plan (read-only: shared by every run of the plan)."""
    table = _horizons(json.dumps(dict(profile.context.values), sort_keys=True))
    table.flags.writeable = False
    return table


def run(profile, plant, controller, columns: int, prune: tuple[RunningIndex, float] | None):
    """The run, compiled: (rows (steps x columns, loop.SERIES), the controller's
    outputs (steps x 5), the horizons)."""
    targets = horizons(profile)
    train, han, limiter = plant.train, controller.controller, controller.limiter
    state = train.state
    running, limit = prune if prune is not None else (RunningIndex("itae"), math.inf)
    rows = np.empty((len(targets), columns))
    extras = np.empty((len(targets), 5))
    # the sensor's draws, as PlantStage.measure takes them (one per step, the same stream)
    draws = plant.rng.standard_normal(len(targets)) if plant.noise > 0.0 else \
        np.zeros(len(targets))
    sensor = (plant.noise, plant.quantum)
    done, running.value, running.last_t, running.last_w = _loop(
        targets, draws, sensor, controller.preview, train.period, train.substeps, train.steps, state.time,
        state.position, state.speed, state.force, train.lag_state, train.acting, train.powered,
        train.constants, train.lagged, train.limited, plant.max_speed,
        (han.eso.z1, han.eso.z2, han.eso.z3, han.td.v1, han.td.v2, han.u_applied),
        han.gains_tuple, han.td.h, limiter.last, limiter.settings,
        running.kind, limit, running.value, running.last_t, running.last_w, rows, extras)
    return rows[:done], extras[:done], targets[:done]


def _loop_source(targets, draws, sensor, preview, period, substeps, plant_steps, time, x, v,
                 force, lag, acting, powered, constants, lagged, limited, max_speed, controller_state,
                 gains, h, last, limits, kind, limit, value, last_t, last_w, rows, extras):
    """simulate()'s loop for the runs `covers` accepts; returns (steps done, running
    index state). Rows in loop.SERIES order."""
    _, a, b, c, amplitude, omega, phase, _, _, _, envelope = constants
    sub = period / substeps
    z1, z2, z3, v1, v2, u_applied = controller_state
    for k in range(len(targets)):
        # plant outputs at t_k (PlantStage.outputs)
        measured = sensor_reading(v, draws[k], sensor[0], sensor[1])
        acceleration = rates(time, v, lag, acting, powered, no_line(x), constants)[0]
        reference = targets[k, preview]
        if k == 0:  # HanADRC.start
            v1, z1 = reference, measured
        u, z1, z2, z3, v1, v2 = han_adrc_step(z1, z2, z3, v1, v2, u_applied, reference,
                                              measured, gains, h, last, limits)
        u_applied = last = u
        row = rows[k]
        row[0], row[1], row[2], row[3], row[4] = k * period, targets[k, 0], x, measured, v
        row[5], row[6], row[7] = acceleration, disturbance(time, amplitude, omega, phase), force
        row[8], row[9], row[10], row[11] = basic_resistance(v, a, b, c), 0.0, math.inf, u
        extras[k, 0], extras[k, 1], extras[k, 2], extras[k, 3], extras[k, 4] = z1, z2, z3, v1, v2
        speed = v
        # plant.apply(u) (PointMassTrain.step)
        start = time
        for i in range(substeps):
            x, v, lag = rk4_substep(start + i * sub, x, v, lag, sub, u, powered, constants,
                                    no_line)
        acting = u
        plant_steps += 1
        time = plant_steps * period
        force = achievable(lag if lagged else u, v, limited, envelope)
        if not (abs(v) <= max_speed):  # PlantStage.diverged
            return k + 1, value, last_t, last_w
        value, last_t, last_w = running_add(kind, value, last_t, last_w, k * period,
                                            targets[k, 0] - speed)
        if value > limit:
            return k + 1, value, last_t, last_w
    return len(targets), value, last_t, last_w


_loop = compiled(_loop_source)
