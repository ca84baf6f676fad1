"""Operation indices of a run: energy, comfort, speed-limit compliance, stopping
and punctuality (ROS-free).

Series are sampled at every control step: t (s), position (m), speed (m/s),
acceleration (m/s^2), force (specific force, N/kN: + traction, - braking) and
optionally speed_limit (m/s, the line limit at the train's position). The force in
kN is force * mass * gravity / 1000 with the mass in t.

- traction_energy_kwh: integral of max(F, 0) max(v, 0) dt / efficiency, kWh drawn
  from the supply.
- regenerated_energy_kwh: integral of min(B, F_r, P_r / v) max(v, 0) dt * eta_r, kWh,
  with B = max(-F, 0) in kN: the drive brakes electrically up to its regenerative force
  F_r (kN) and power P_r (kW), the rest of the braking is pneumatic and regenerates
  nothing; eta_r the regeneration efficiency (`Regeneration`). Its defaults are no
  limits and eta_r = efficiency: all braking regenerative at the traction's efficiency.
- net_energy_kwh: traction minus regenerated, kWh.
- max_jerk: largest mean jerk over JERK_WINDOW (1 s): |a(t + 1 s) - a(t)| / 1 s, m/s^3.
  Comfort standards judge jerk over about a second (EN 12299 smooths over 1 s); a
  sampled step in the acceleration -- the end of braking as the train stops, a
  neutral section -- counts as its size per second, not per control period.
- max_jerk_sampled: largest |da/dt| between consecutive samples, m/s^3.
- comfort_index: sum of |change of acceleration| per unit time (seed 002), m/s^3.
- switch_count: changes between traction and braking; coasting does not end a mode.
- overspeed_time (s), max_overspeed_kmh (km/h): time above and largest excess over
  the speed limit, only when speed_limit is given.
- stopping_error (m, + overshoot), abs_stopping_error (m): final position against
  stop_position, only when it is given; overrun: 1 when the train stopped more than
  BERTHING_TOLERANCE past its mark (its doors miss the platform's: an outcome an
  operator names and acts on), else 0.
- arrival_time (s): t of the first sample of the final standstill (speed <= 0.01
  m/s); NaN if the train is still moving at the end or never moved.
- running_time_error (s, + late): arrival_time - planned_run_time, when planned;
  abs_running_time_error (s): its size, punctuality either way.
- neutral_traction_command_time, neutral_traction_force_time (s): time the command,
  and the force applied, is traction (> 0) with the pantograph inside a neutral section
  (a real ATO commands none across a phase break: it opens the main circuit breaker),
  each sample counting until the next, as overspeed_time does; only when told at which
  samples the pantograph is inside one (a line with neutral sections).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.kernels import jitable
from ..base.units import MS_TO_KMH
from .indices import _integral

STANDSTILL = 0.01  # m/s
JERK_WINDOW = 1.0  # s
KJ_PER_KWH = 3600.0
# m past the mark a metro's platform tolerates (platform screen doors; docs/localisation.md)
BERTHING_TOLERANCE = 0.3


SWITCH_THRESHOLD = 0.5  # N/kN: a force this small or smaller is coasting


def drive_modes(force: np.ndarray, threshold: float = SWITCH_THRESHOLD) -> np.ndarray:
    """+1 traction, -1 braking, 0 coasting, per step."""
    return np.where(np.abs(force) > threshold, np.sign(force), 0).astype(int)


def _switch_count(force: np.ndarray, threshold: float) -> int:
    """Changes between traction and braking (coasting in between does not count)."""
    modes = drive_modes(force, threshold)
    return int(np.count_nonzero(np.diff(modes[modes != 0])))


def windowed_jerk(t: np.ndarray, acceleration: np.ndarray, window: float = JERK_WINDOW
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(centre times, mean jerk over `window`): max_jerk is its largest magnitude."""
    lag = max(1, min(len(t) - 1, round(window / float(np.median(np.diff(t))))))
    jerk = (acceleration[lag:] - acceleration[:-lag]) / (t[lag:] - t[:-lag])
    return (t[lag:] + t[:-lag]) / 2, jerk


def _arrival_time(t: np.ndarray, speed: np.ndarray) -> float:
    moving = np.flatnonzero(speed > STANDSTILL)
    if len(moving) == 0 or moving[-1] == len(speed) - 1:
        return float("nan")
    return float(t[moving[-1] + 1])


class Regeneration(NamedTuple):
    """How a train's braking regenerates: electrically up to min(force, power / v), the
    real train's (kN, kW; inf: no limit), the rest pneumatic; the electric part returned
    to the supply at `efficiency` (None: the traction efficiency)."""

    force: float = math.inf       # kN
    power: float = math.inf       # kW
    efficiency: float | None = None

    @classmethod
    def of(cls, values) -> Regeneration:
        """From a run's plant.regenerative_* values: limits only with plant.regenerative_
        limits, an efficiency only above 0 (a run recorded without them had neither)."""
        limited = values.get("plant.regenerative_limits", False)
        efficiency = float(values.get("plant.regenerative_efficiency", 0.0))
        return cls(values["plant.regenerative_force"] if limited else math.inf,
                   values["plant.regenerative_power"] if limited else math.inf,
                   efficiency if efficiency > 0.0 else None)

    def electric_power(self, brake: np.ndarray, speed: np.ndarray) -> np.ndarray:
        """The braking power the drive regenerates (before its efficiency), kW, of the
        braking force `brake` (kN, >= 0) at `speed` (m/s, >= 0)."""
        return electric_force(brake, speed, self.force, self.power) * speed

    def returned(self, efficiency: float) -> float:
        """The regeneration efficiency, the traction's `efficiency` where none is given."""
        return efficiency if self.efficiency is None else self.efficiency


@jitable
def electric_force(brake, speed, force, power):
    """The share of the braking force `brake` (kN, >= 0) at `speed` (m/s, >= 0) that the
    drive brakes electrically, min(B, F_r, P_r / v), kN (F_r kN, P_r kW; inf: no limit);
    the rest is pneumatic."""
    return np.minimum(np.minimum(brake, force), power / np.maximum(speed, 1e-9))


ALL_REGENERATIVE = Regeneration()  # today's model: every brake force regenerates


def traction_energy_kwh(t: np.ndarray, speed: np.ndarray, force: np.ndarray, mass: float,
                        gravity: float = 9.8, efficiency: float = 0.9) -> float:
    """Energy drawn from the supply for traction over the samples, kWh (force in N/kN,
    mass in t: the module docstring's traction_energy_kwh)."""
    force_kn = np.asarray(force, dtype=float) * mass * gravity / 1000.0
    drawn = np.maximum(force_kn, 0.0) * np.maximum(np.asarray(speed, dtype=float), 0.0)
    return _integral(np.asarray(t, dtype=float), drawn) / efficiency / KJ_PER_KWH


def neutral_traction_time(t: np.ndarray, signal: np.ndarray, neutral: np.ndarray) -> float:
    """Time `signal` (a command or force, N/kN) is traction with the pantograph inside a
    neutral section (`neutral`, per sample), s: each such sample counts until the next."""
    traction = (np.asarray(signal, dtype=float) > 0.0) & np.asarray(neutral, dtype=bool)
    return float(np.sum(np.diff(np.asarray(t, dtype=float))[traction[:-1]]))


def operation_indices(series: dict[str, np.ndarray], mass: float, gravity: float = 9.8,
                      efficiency: float = 0.9, stop_position: float | None = None,
                      planned_run_time: float | None = None,
                      switch_threshold: float = SWITCH_THRESHOLD,
                      neutral: np.ndarray | None = None,
                      regeneration: Regeneration = ALL_REGENERATIVE) -> dict[str, float]:
    """Every operation index of a run, as a flat dict (see the module docstring);
    `neutral` the samples with the pantograph inside a neutral section, `regeneration`
    how the braking regenerates (default: all of it, at `efficiency`)."""
    t, position, speed, acceleration, force = (
        np.asarray(series[name], dtype=float)
        for name in ("t", "position", "speed", "acceleration", "force"))
    force_kn = force * mass * gravity / 1000.0
    v = np.maximum(speed, 0.0)
    traction = traction_energy_kwh(t, speed, force, mass, gravity, efficiency)
    regenerated = (_integral(t, regeneration.electric_power(np.maximum(-force_kn, 0.0), v))
                   * regeneration.returned(efficiency) / KJ_PER_KWH)
    dt = np.diff(t)
    da = np.diff(acceleration)
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    arrival = _arrival_time(t, speed)
    result = {
        "traction_energy_kwh": traction,
        "regenerated_energy_kwh": regenerated,
        "net_energy_kwh": traction - regenerated,
        "max_jerk": float(np.max(np.abs(windowed_jerk(t, acceleration)[1]))) if len(t) > 1
        else 0.0,
        "max_jerk_sampled": float(np.max(np.abs(da / dt))) if len(t) > 1 else 0.0,
        "comfort_index": float(np.sum(np.abs(da))) / span if span > 0 else 0.0,
        "switch_count": _switch_count(force, switch_threshold),
        "arrival_time": arrival,
    }
    if "speed_limit" in series:
        excess = speed - np.asarray(series["speed_limit"], dtype=float)
        result["overspeed_time"] = float(np.sum(dt[excess[:-1] > 0.0]))
        result["max_overspeed_kmh"] = (float(max(np.max(excess), 0.0)) * MS_TO_KMH
                                       if len(excess) else 0.0)
    if stop_position is not None:
        result["stopping_error"] = float(position[-1] - stop_position)
        result["abs_stopping_error"] = abs(result["stopping_error"])
        result["overrun"] = float(result["stopping_error"] > BERTHING_TOLERANCE)
    if planned_run_time is not None:
        result["running_time_error"] = arrival - planned_run_time
        result["abs_running_time_error"] = abs(result["running_time_error"])
    if neutral is not None:
        if "command" in series:
            result["neutral_traction_command_time"] = neutral_traction_time(
                t, series["command"], neutral)
        result["neutral_traction_force_time"] = neutral_traction_time(t, force, neutral)
    return result


# The console lines that judge a run's one stop: a journey's say which stop they are of.
STOP_LINES = ("stopping_error", "arrival_time", "running_time_error")


def _stop_text(text: str, value: float, last_stop: tuple[str, str]) -> str:
    """A journey's stop index as text: of its last stop, or the word for why there is
    none (`last_stop`: which stop, that word)."""
    where, missing = last_stop
    return f"{text} at {where}" if np.isfinite(value) else f"{missing}: {where}"


def format_operation(indices: dict, last_stop: tuple[str, str] | None = None) -> list[str]:
    """Human-readable lines for whichever operation indices are present; a journey's
    stop lines name its last stop (`last_stop`: which, and the word for no stop there,
    e.g. "not reached")."""
    formats = [
        ("traction_energy_kwh", "traction energy", "{:.2f} kWh"),
        ("regenerated_energy_kwh", "regenerated", "{:.2f} kWh"),
        ("net_energy_kwh", "net energy", "{:.2f} kWh"),
        ("max_jerk", "max jerk (1 s)", "{:.4g} m/s^3"),
        ("max_jerk_sampled", "max jerk (step)", "{:.4g} m/s^3"),
        ("comfort_index", "comfort index", "{:.4g} m/s^3"),
        ("switch_count", "switches", "{}"),
        ("overspeed_time", "overspeed time", "{:.2f} s"),
        ("max_overspeed_kmh", "max overspeed", "{:.3f} km/h"),
        ("stopping_error", "stopping error", "{:+.3f} m"),
        ("arrival_time", "arrival time", "{:.2f} s"),
        ("running_time_error", "running-time err", "{:+.2f} s"),
        ("neutral_traction_command_time", "neutral traction", "{:.1f} s commanded"),
        ("neutral_traction_force_time", "neutral traction", "{:.1f} s applied"),
    ]
    lines = []
    for key, label, fmt in formats:
        if key not in indices:
            continue
        text = fmt.format(indices[key])
        if last_stop is not None and key in STOP_LINES:
            text = _stop_text(text, indices[key], last_stop)
        lines.append(f"{label:<17}{text}")
    return lines
