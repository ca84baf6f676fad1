"""Tracking performance indices from sampled time series (ROS-free).

Integrals use the trapezoidal rule over the samples. The tracking error is
e = target - true speed, in m/s; `*_kmh` fields are the same in km/h.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from ..base.units import MS_TO_KMH


def _integral(t: np.ndarray, y: np.ndarray) -> float:
    return float(np.trapezoid(y, t)) if len(t) > 1 else 0.0


def itae(t: np.ndarray, error: np.ndarray) -> float:
    """Integral of t |e(t)| dt (seed 000 eq. 24), m*s... i.e. (m/s) s^2."""
    return _integral(t, t * np.abs(error))


def iae(t: np.ndarray, error: np.ndarray) -> float:
    return _integral(t, np.abs(error))


def ise(t: np.ndarray, error: np.ndarray) -> float:
    return _integral(t, error * error)


def seed004_j(t: np.ndarray, error: np.ndarray, command: np.ndarray,
              w1: float = 1.0, w2: float = 10.0) -> float:
    """Seed 004's J = integral of (w1 |e| + w2 u^2) dt."""
    return _integral(t, w1 * np.abs(error) + w2 * command * command)


def tracking_indices(t: np.ndarray, target: np.ndarray, speed: np.ndarray,
                     command: np.ndarray | None = None) -> dict[str, float]:
    """Every tracking index the scorer knows, as a flat dict of floats."""
    t, target, speed = (np.asarray(a, dtype=float) for a in (t, target, speed))
    error = target - speed
    finite = bool(np.all(np.isfinite(error)))
    max_abs = float(np.max(np.abs(error))) if len(error) else 0.0
    result = {
        "steps": int(len(t)),
        "finite": finite,
        "itae": itae(t, error),
        "iae": iae(t, error),
        "ise": ise(t, error),
        "max_abs_error": max_abs,
        "max_abs_error_kmh": max_abs * MS_TO_KMH,
        "median_abs_error_kmh": float(np.median(np.abs(error))) * MS_TO_KMH if len(error) else 0.0,
        "p95_abs_error_kmh": (float(np.percentile(np.abs(error), 95)) * MS_TO_KMH
                              if len(error) else 0.0),
    }
    if command is not None:
        result["j_seed004"] = seed004_j(t, error, np.asarray(command, dtype=float))
    return result


# The running indices' kinds, as compiled code reads them: positions in RunningIndex.MONOTONE.
ITAE, IAE, MAX_ABS_ERROR = range(3)


@jitable
def running_add(kind: int, value: float, last_t: float, last_w: float, t: float,
                error: float) -> tuple[float, float, float]:
    """RunningIndex.add on its state (value, last_t, last_w; last_t NaN before the
    first sample): the state after adding (t, error); `kind` ITAE, IAE or MAX_ABS_ERROR."""
    magnitude = abs(error)
    if kind == MAX_ABS_ERROR:
        return max(value, magnitude), last_t, last_w
    weighted = t * magnitude if kind == ITAE else magnitude
    if last_t == last_t:  # not NaN: a previous sample exists
        value += 0.5 * (t - last_t) * (weighted + last_w)
    return value, t, weighted


class RunningState(NamedTuple):
    """A RunningIndex's value so far and its last sample (last_t NaN before the first)."""

    value: float
    last_t: float
    last_w: float


RUNNING_START = RunningState(0.0, math.nan, 0.0)


@jitable
def running_step(kind: int, state: RunningState, t: float, error: float) -> RunningState:
    """The state after adding the sample (t, error) (running_add)."""
    return RunningState(*running_add(kind, state.value, state.last_t, state.last_w, t, error))


class RunningIndex:
    """ITAE, IAE or max abs(e) (m/s) of a run so far, one sample at a time, by the same
    trapezoid rule as tracking_indices: each only grows along a run, so a run whose
    value has passed a bound ends above it (a tuner's pruning). Summed step by step,
    it may differ from the whole run's numpy sum in the last digits."""

    MONOTONE = ("itae", "iae", "max_abs_error")  # in the order of ITAE, IAE, MAX_ABS_ERROR

    def __init__(self, name: str):
        if name not in self.MONOTONE:
            raise ValueError(f"{name} does not only grow along a run")
        self.name = name
        self.kind = self.MONOTONE.index(name)
        self.state = RUNNING_START

    @property
    def value(self) -> float:
        return self.state.value

    def add(self, t: float, error: float) -> float:
        self.state = running_step(self.kind, self.state, t, error)
        return self.value
