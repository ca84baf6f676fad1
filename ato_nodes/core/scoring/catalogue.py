"""The indices a run is scored on, as names: every index the scorer gives, those that only
grow along a run, those that judge its stop, the fitnesses a tuning minimises, a
requirement on an index (`name<=limit`) and the console table of a run's indices.
Known to the configuration (report.require is checked against it) and to every
scorer; computed by core/run/scoring.py from core/scoring/indices.py and operation.py."""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Any

from ..base.errors import ScenarioError
from .journey import format_journey
from .operation import format_operation

# Every index score_series can give (a run gives those that apply to it).
INDEX_NAMES = (
    "steps", "finite", "itae", "iae", "ise", "max_abs_error", "max_abs_error_kmh",
    "median_abs_error_kmh", "p95_abs_error_kmh", "j_seed004",
    "eso_speed_max_dev", "eso_acceleration_max_dev", "eso_disturbance_max_dev",
    "overshoot_percent", "traction_energy_kwh", "regenerated_energy_kwh", "net_energy_kwh",
    "max_jerk", "max_jerk_sampled", "comfort_index", "switch_count", "overspeed_time",
    "max_overspeed_kmh", "stopping_error", "abs_stopping_error", "overrun", "arrival_time",
    "running_time_error", "abs_running_time_error", "neutral_traction_command_time",
    "neutral_traction_force_time", "max_abs_error_outside_steps_kmh", "stepped_time")
# The worst station of a journey run, as studies and tunings count it
# (results/journeys.worst_stations; inf: a station missed or not reached, which no bound
# admits); a TTOBench journey's timing points not kept. A journey run's only.
WORST_STOP, WORST_ARRIVAL = "journey_worst_stop_m", "journey_worst_arrival_s"
TIMING_MISSED = "journey_timing_points_missed"
JOURNEY_INDICES = (WORST_STOP, WORST_ARRIVAL, TIMING_MISSED)
# Those that only grow along a run (integrals of non-negative terms, maxima, counts):
# a partial run that breaks a requirement on one of them has broken it for good.
GROWING_INDICES = (
    "itae", "iae", "ise", "max_abs_error", "max_abs_error_kmh", "j_seed004",
    "traction_energy_kwh", "regenerated_energy_kwh", "max_jerk", "max_jerk_sampled",
    "switch_count", "overspeed_time", "max_overspeed_kmh", "neutral_traction_command_time",
    "neutral_traction_force_time", "max_abs_error_outside_steps_kmh", "stepped_time")
# Those that judge the run's stop: they say nothing of a run that ended short of it.
STOP_INDICES = ("stopping_error", "abs_stopping_error", "overrun", "arrival_time",
                "running_time_error", "abs_running_time_error")
# A tuning's fitness (tune.py --fitness) -> the index it minimises.
FITNESS = {"itae": "itae", "j": "j_seed004", "iae": "iae", "max_abs_error": "max_abs_error",
           "p95_abs_error_kmh": "p95_abs_error_kmh"}
# A multi-objective tuning's objectives (tune.py --objectives): any index with a size
# (not a sign, a count of steps or a verdict) by its name, or by a fitness's or these
# short names; each minimised but those more of which is better.
NOT_OBJECTIVES = ("steps", "finite", "stopping_error", "overrun", "running_time_error")
MAXIMISED = ("regenerated_energy_kwh",)
OBJECTIVE_NAMES = {**FITNESS, "energy": "traction_energy_kwh", "net_energy": "net_energy_kwh",
                   "jerk": "max_jerk", "comfort": "comfort_index", "stop": "abs_stopping_error",
                   "punctuality": "abs_running_time_error",
                   "worst_stop": WORST_STOP, "worst_arrival": WORST_ARRIVAL,
                   **{name: name for name in INDEX_NAMES + JOURNEY_INDICES
                      if name not in NOT_OBJECTIVES}}


def objective_index(name: str, source: str = "--objectives") -> str:
    """The index an objective `name` names; one ScenarioError naming `source` otherwise."""
    index = OBJECTIVE_NAMES.get(name.strip())
    if index is None:
        close = difflib.get_close_matches(name.strip(), OBJECTIVE_NAMES, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise ScenarioError(f"{source}: {name.strip()!r} is not an objective{hint}; an index "
                            "with a size (e.g. energy, itae, p95_abs_error_kmh, max_jerk)")
    return index


@dataclass(frozen=True)
class Requirement:
    """An operational requirement on an index, `name<=limit`: a candidate that breaks
    it is infeasible, whatever its fitness (a controller that never leaves the
    platform tracks a position-indexed target well: 0.3 m/s off, standing still)."""

    name: str
    limit: float

    @classmethod
    def parse(cls, text: str, source: str = "--require",
              names: tuple[str, ...] = INDEX_NAMES + JOURNEY_INDICES) -> Requirement:
        """`name<=limit` on one of `names` (a tuning's and a study's: a journey's worst
        station too); anything else is one ScenarioError naming `source`."""
        name, sep, limit = text.partition("<=")
        try:
            requirement = cls(name.strip(), float(limit)) if sep else cls._bad(text, source)
        except ValueError:
            return cls._bad(text, source)
        if not math.isfinite(requirement.limit):
            raise ScenarioError(f"{source}: the limit of {requirement.name} must be a finite "
                                f"number, not {limit.strip()!r}")
        if requirement.name not in names:
            close = difflib.get_close_matches(requirement.name, names, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise ScenarioError(f"{source}: unknown index {requirement.name!r}{hint}")
        return requirement

    @classmethod
    def parse_list(cls, text: str, source: str) -> tuple[Requirement, ...]:
        """A comma-separated list (a scenario's report.require: the indices a run's
        report gives)."""
        return tuple(cls.parse(item, source, INDEX_NAMES) for item in text.split(",")
                     if item.strip())

    @staticmethod
    def _bad(text: str, source: str):
        raise ScenarioError(f"{source} expects INDEX<=VALUE (e.g. abs_stopping_error<=0.3), "
                            f"got {text!r}")

    def violation(self, indices: dict[str, Any]) -> float:
        """0 when met; else how far it is broken, relative to max(|limit|, 1)."""
        return max(0.0, self.signed_violation(indices))

    def signed_violation(self, indices: dict[str, Any]) -> float:
        """How far the index is past its limit, relative to max(|limit|, 1): <= 0 when
        met (how far inside), 1e3 when the run has no finite value of it."""
        value = indices.get(self.name, math.nan)
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            return 1e3
        return (value - self.limit) / max(abs(self.limit), 1.0)


def format_indices(indices: dict) -> str:
    return "\n".join([
        f"steps            {indices['steps']}",
        f"ITAE             {indices['itae']:.6g}  (m/s) s^2",
        f"IAE              {indices['iae']:.6g}  m",
        f"ISE              {indices['ise']:.6g}  m^2/s",
        f"max |e|          {indices['max_abs_error_kmh']:.4f} km/h"
        f"  ({indices['max_abs_error']:.5f} m/s)",
        f"median |e|       {indices['median_abs_error_kmh']:.4f} km/h",
        f"p95 |e|          {indices['p95_abs_error_kmh']:.4f} km/h",
        f"J (seed 004)     {indices.get('j_seed004', float('nan')):.6g}",
        *([f"ESO max |z1 - v| {indices['eso_speed_max_dev']:.3g} m/s, |z2 - a| "
           f"{indices['eso_acceleration_max_dev']:.3g} m/s^2, |z3 - f| "
           f"{indices['eso_disturbance_max_dev']:.3g} m/s^3"]
          if "eso_speed_max_dev" in indices else []),
        *([f"overshoot        {indices['overshoot_percent']:.3f} %"]
          if "overshoot_percent" in indices else []),
        *([f"max |e| o. steps {indices['max_abs_error_outside_steps_kmh']:.4f} km/h outside "
           f"{indices['stepped_time']:.1f} s of stepped approach"]
          if "max_abs_error_outside_steps_kmh" in indices else []),
        *format_operation(indices, journey_last_stop(indices.get("journey"))),
        *(format_journey(indices["journey"]) if "journey" in indices else []),
    ])


def journey_last_stop(journey: dict | None) -> tuple[str, str] | None:
    """A journey's last stop, as its stop indices name it (format_operation): which,
    and the word for no stop there (e.g. "not reached"); None for another run (no
    `journey`, journey.journey_record)."""
    if journey is None:
        return None
    if "error" in journey:
        return "the last stop (no per-station results)", "not judged"
    last = journey["stations"][-1]
    return f"{last['station']}, the last stop", last["outcome"]
