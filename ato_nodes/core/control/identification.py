"""Seed 001's identification pipeline, ROS-free: excitation targets, samples from runs,
the hyperparameter search, the linear multi-model, free-run prediction, the models'
error figures and the study of online correction on a changed train.

Data: the project's own plant (the CRH380AL preset with its envelopes, lag, dead
time and a noisy speed sensor) run through the stack, not the paper's Xuzhou East -
Jinan West records. Excitation: a PID tracks a random staircase of speeds (levels
uniform over the speed range, reached by ramps steeper than the train can follow,
held 30-90 s, with ripples of a few km/h every 5-15 s). Why: the steep ramps drive
the train to its full traction and braking envelope, the ripples make the command
move around every cruising level (a model of cruise alone sees only u ~ w0(v)),
and the staircase keeps the speed inside the range; an open-loop random command
would drift out of it.

The models' command input is the effective command: the recorded command clipped to
the nominal train's traction and brake envelope at the measured speed. The part of a
command beyond the envelope does nothing; samples of it teach the kernel a flat
response to the command (measured: with raw commands, 22 % of the validation run's
linearisations had a negative input gain, fatal for a predictive controller).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..base.units import KMH, MS_TO_KMH
from ..optimizers import optimize
from . import lssvm
from .gpc_steps import MultiModel, blended_row


def excitation_table(seed: int, duration: float, top_speed: float) -> list[tuple[float, float]]:
    """(time s, speed m/s) rows of a seeded random staircase with ripples (module doc)."""
    rng = np.random.default_rng(seed)
    rows, t, speed = [(0.0, 0.0)], 0.0, 0.0
    while t < duration:
        level = float(rng.uniform(0.1, 1.0) * top_speed)
        ramp = abs(level - speed) / 1.0  # 1 m/s^2: steeper than the train's envelope
        t += max(ramp, 1.0)
        rows.append((t, level))
        hold_end = t + rng.uniform(30.0, 90.0)
        while t < hold_end:
            t += rng.uniform(5.0, 15.0)
            rows.append((t, max(0.0, level + rng.uniform(-5.0, 5.0) * KMH)))
        speed = rows[-1][1]
    t += speed / 0.5 + 10.0
    rows.append((t, 0.0))
    return rows


def effective_commands(train, speeds: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """Each command clipped to what `train` (core.plant.TrainParameters) can apply at
    the measured speed of its step."""
    limits = np.array([train.force_limits(v) for v in speeds])
    return np.clip(commands, limits[:, 0], limits[:, 1])


def sample_steps(length: int, layout: lssvm.Layout, count: int) -> np.ndarray:
    """`count` steps evenly spread over a run of `length` steps, each with its history."""
    first = max(layout.speed_lags, layout.history)
    if length - first < count:
        raise ValueError(f"a run of {length} steps holds fewer than {count} samples")
    return np.linspace(first, length - 1, count).round().astype(int)


@dataclass(frozen=True)
class Recording:
    """A recorded run as the models see it, step by step: the measured speeds (m/s)
    and the effective commands (N/kN, effective_commands())."""
    speeds: np.ndarray
    commands: np.ndarray


def spread_samples(layout: lssvm.Layout, recordings: Sequence[Recording], total: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """`total` samples (regressors, targets) spread over the recordings in proportion
    to their lengths, each recording's evenly over it (sample_steps()). Raises
    ValueError when a recording is too short for its share."""
    lengths = np.array([len(recording.speeds) for recording in recordings])
    counts = np.diff(np.round(np.concatenate([[0], np.cumsum(lengths)])
                              * total / lengths.sum()).astype(int))
    parts = [layout.samples(recording.speeds, recording.commands,
                            sample_steps(len(recording.speeds), layout, count))
             for recording, count in zip(recordings, counts, strict=True)]
    return np.concatenate([x for x, _ in parts]), np.concatenate([t for _, t in parts])


def split(count: int, train: int) -> tuple[np.ndarray, np.ndarray]:
    """Training and test indices of `count` samples in time order, interleaved so both
    cover the whole run: sample i is a training sample when floor((i + 1) train /
    count) > floor(i train / count) (900 of 1500: three of every five)."""
    i = np.arange(count)
    is_train = (i + 1) * train // count > i * train // count
    return i[is_train], i[~is_train]


@dataclass
class Search:
    mu: float
    delta: float
    rmse: float
    result: object  # optimizers.Result


# Search box: log10 mu over the paper's (0.001, 8000); delta over (0, 5], floored at 0.01.
LOG_MU = (-3.0, math.log10(8000.0))
DELTA = (0.01, 5.0)


def validation_split(x: np.ndarray, t: np.ndarray):
    """The training samples, split again (interleaved, 2:1) into a fitting and a
    validation part: the search's RMSE is measured on samples the fit has not seen
    (on its own samples the RMSE only falls as mu grows and delta shrinks)."""
    fit_rows, check_rows = split(len(t), (2 * len(t)) // 3)
    return x[fit_rows], t[fit_rows], x[check_rows], t[check_rows]


def validation_rmse(layout, x_fit, t_fit, x_check, t_check, mu, delta) -> float:
    try:
        model = lssvm.fit(layout, x_fit, t_fit, mu, delta)
    except ValueError:
        return math.inf
    error = model.increment(x_check) - t_check
    return float(np.sqrt(np.mean(error * error)))


def search_hyperparameters(layout: lssvm.Layout, x: np.ndarray, t: np.ndarray, *,
                           seed: int = 1, population: int = 40, iterations: int = 100) -> Search:
    """(mu, delta) by the paper's adaptive-inertia PSO (N 40, M 100, c1 = c2 = 2, w in
    [0.4, 0.9]) minimising the validation RMSE, searching log10 mu (the paper searches
    mu linearly over (0.001, 8000): a linear search never looks below ~10)."""
    parts = validation_split(x, t)

    def fitness(candidates: np.ndarray) -> np.ndarray:
        return np.array([validation_rmse(layout, *parts, 10.0 ** c[0], c[1])
                         for c in candidates])

    result = optimize("aw-pso", fitness, [LOG_MU[0], DELTA[0]], [LOG_MU[1], DELTA[1]],
                      budget=population * (iterations + 1), seed=seed,
                      population_size=population)
    return Search(10.0 ** result.best_x[0], float(result.best_x[1]), result.best_f, result)


def at_bound(search: Search) -> list[str]:
    """The hyperparameters the search left within 0.1 % of the box's edge (the box may
    have cut the optimum off)."""
    return [name for name, value, (low, high) in (("mu", math.log10(search.mu), LOG_MU),
                                                   ("delta", search.delta, DELTA))
            if not low + 1e-3 * (high - low) < value < high - 1e-3 * (high - low)]


def grid_around(layout, x, t, mu: float, delta: float, factor: float = 2.0, points: int = 5):
    """Validation RMSE on a log grid of mu and delta around (mu, delta), from mu/factor
    to mu*factor and the same for delta, inside the search box (a point on its edge is
    checked against its neighbours inside): rows mu, columns delta."""
    parts = validation_split(x, t)
    mus = np.clip(mu * factor ** np.linspace(-1, 1, points), *(10.0 ** np.array(LOG_MU)))
    deltas = np.clip(delta * factor ** np.linspace(-1, 1, points), *DELTA)
    table = np.array([[validation_rmse(layout, *parts, m, d) for d in deltas] for m in mus])
    return mus, deltas, table


def fit_multimodel(layout: lssvm.Layout, x: np.ndarray, t: np.ndarray, centres: np.ndarray,
                   width: float) -> np.ndarray:
    """The linear multi-model: per centre speed, an ARX model y(k) = c + sum a_j y(k-j)
    + sum b_j u(k-nk-j) fitted by least squares with Gaussian weights of y(k-1) about
    the centre (width the weights' standard deviation, m/s). Rows [c, a.., b..]."""
    design = np.column_stack([np.ones(len(t)), x])
    y = t + x[:, 0]
    rows = []
    for centre in centres:
        weight = np.sqrt(np.exp(-0.5 * ((x[:, 0] - centre) / width) ** 2))
        coefficients, *_ = np.linalg.lstsq(design * weight[:, None], y * weight, rcond=None)
        rows.append(coefficients)
    return np.array(rows)


def free_run(step, layout: lssvm.Layout, speeds: np.ndarray, commands: np.ndarray,
             start: int | None = None) -> np.ndarray:
    """The model's own speed over a recorded run: the measured history up to `start`
    (default: the first step with a full history), then driven by the recorded commands
    alone, each prediction fed back as the next regressor's speed. step(x) -> y(k)."""
    first = max(layout.speed_lags, layout.history)
    predicted = speeds.astype(float)
    for k in range(first if start is None else start, len(speeds)):
        predicted[k] = step(layout.regressor(predicted[:k], commands[:k]))
    return predicted


def ahead(step, layout: lssvm.Layout, speeds: np.ndarray, commands: np.ndarray, count: int,
          every: int = 10) -> np.ndarray:
    """Errors of `count`-step-ahead predictions (what a GPC with horizon P = count relies
    on): from every `every`-th step, a free run of `count` steps from the measured
    history; the error of its last step, m/s."""
    first = max(layout.speed_lags, layout.history)
    return np.array([free_run(step, layout, speeds[:start + count], commands[:start + count],
                              start)[-1] - speeds[start + count - 1]
                     for start in range(first, len(speeds) - count, every)])


# The models' errors, in km/h: one step ahead, free run, AHEAD steps ahead.

AHEAD = 20  # steps: the shipped GPC's prediction horizon


def error_ranges(errors: np.ndarray) -> dict:
    """Smallest, largest and RMS of errors given in m/s, in km/h."""
    errors = errors * MS_TO_KMH
    return {"min_kmh": float(errors.min()), "max_kmh": float(errors.max()),
            "rms_kmh": float(np.sqrt(np.mean(errors ** 2)))}


def within_ctcs3(errors: np.ndarray, speeds: np.ndarray) -> float:
    """Share of samples inside the CTCS-3 speed-measurement tolerance: 2 km/h below
    30 km/h, 2 % of the speed above."""
    tolerance = np.where(speeds * MS_TO_KMH < 30.0, 2.0, 0.02 * speeds * MS_TO_KMH)
    return float(np.mean(np.abs(errors * MS_TO_KMH) <= tolerance))


def one_step_errors(model: lssvm.LSSVM, x: np.ndarray, t: np.ndarray) -> dict:
    """error_ranges() of the model's one-step predictions of samples (x, t), and the
    share inside the CTCS-3 tolerance."""
    errors = model.increment(x) - t
    return {**error_ranges(errors), "within_ctcs3": within_ctcs3(errors, x[:, 0])}


def prediction_errors(step: Callable[[np.ndarray], float], layout: lssvm.Layout,
                      recording: Recording) -> dict:
    """error_ranges() of the free run over the whole recording and of the AHEAD-step-ahead
    predictions. step(x) -> y(k), as free_run() takes it."""
    speeds, commands = recording.speeds, recording.commands
    return {"free_run": error_ranges(free_run(step, layout, speeds, commands) - speeds),
            f"ahead_{AHEAD}": error_ranges(ahead(step, layout, speeds, commands, AHEAD))}


def lssvm_step(model: lssvm.LSSVM) -> Callable[[np.ndarray], float]:
    return lambda x: x[0] + float(model.increment(x)[0])


def multimodel_step(layout: lssvm.Layout, centres: np.ndarray, width: float,
                    coefficients: np.ndarray) -> Callable[[np.ndarray], float]:
    model = MultiModel(centres, width, coefficients)  # as the GPC blends them

    def step(x: np.ndarray) -> float:
        row = blended_row(model, x[0])
        return float(row[0] + row[1:] @ x)
    return step


def correction_study(offline: lssvm.LSSVM, layout: lssvm.Layout, recording: Recording, *,
                     samples: int, window: int, threshold_kmh: float) -> dict:
    """Stream `samples` samples of a changed train's recording through the online
    correction (every other of 2 x `samples` spread over it; the rest are held out);
    the one-step error on the held-out samples and the free run before and after;
    the cost of every update; the drift from a fresh solve."""
    x, t = layout.samples(recording.speeds, recording.commands,
                          sample_steps(len(recording.speeds), layout, 2 * samples))
    stream, held_out = np.arange(0, len(t), 2), np.arange(1, len(t), 2)
    model = offline.with_window(window)
    threshold = threshold_kmh / MS_TO_KMH
    costs = []
    for i in stream:
        error = float(model.increment(x[i])[0]) - t[i]
        if abs(error) > threshold:
            started = time.perf_counter()
            model.add(x[i], t[i])
            costs.append(time.perf_counter() - started)
    result = {
        "threshold_kmh": threshold_kmh, "window": window,
        "samples_streamed": int(len(stream)), "added": model.added,
        "rejected_by_guard": model.rejected, "forgotten": model.forgotten,
        "one_step_before": error_ranges(offline.increment(x[held_out]) - t[held_out]),
        "one_step_after": error_ranges(model.increment(x[held_out]) - t[held_out]),
        "before": prediction_errors(lssvm_step(offline), layout, recording),
        "after": prediction_errors(lssvm_step(model), layout, recording),
        "drift_from_fresh_solve": drift_from_fresh_solve(offline, x[stream], t[stream], x),
    }
    if costs:
        costs = np.array(costs) * 1e3
        result["update_ms"] = {"median": float(np.median(costs)),
                               "p99": float(np.percentile(costs, 99))}
    return result


def drift_from_fresh_solve(offline: lssvm.LSSVM, x_added: np.ndarray, t_added: np.ndarray,
                           x: np.ndarray) -> dict:
    """How far the predictions on `x` of the offline model with every added sample
    forced in (the recursive updates) lie from a fresh solve of the same samples:
    with a window that keeps them all, then with one a fifth as long (forgetting)."""
    drift = {}
    for window in (len(t_added), len(t_added) // 5):
        forced = offline.with_window(window)
        for sample, target in zip(x_added, t_added, strict=True):
            forced.add(sample, target)
        fresh = forced.refit()
        drift[f"window_{window}"] = {
            "updates": forced.added, "forgotten": forced.forgotten,
            "max_kmh": float(np.abs(fresh.increment(x) - forced.increment(x)).max()) * MS_TO_KMH}
    return drift
