#!/usr/bin/env python3
"""What the departure ramp (profile.departure_jerk) changes: each scenario's nominal run
in-process with the start speed at once (profile.departure_jerk=0) and as shipped, side by
side: max abs(e) and when, the worst in the first 10 s and after the first second, the
stop (a journey's worst station) and the arrival (a journey's worst), max jerk over 1 s.

    python scripts/compare_departure.py seed004-metro-ato seed003-maglev-ato \
        seed004-metro-line

The stack gives the same series bit for bit (scripts/compare_scenarios.py
SCENARIO:profile.departure_jerk=0 SCENARIO checks it and adds p95, ITAE and energy).
"""

from __future__ import annotations

import math

import numpy as np

import _cli

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.units import KMH
from ato_nodes.core.config.scenario import prepare
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.run.scoring import score_series
from ato_nodes.results.journeys import (WORST_ARRIVAL, WORST_STOP, run_journey, run_timetable,
                                        worst_stations)

TARGETS = {"step": ["profile.departure_jerk=0"], "ramp": []}
FIRST_SECONDS = 10.0  # s: where a departure's error shows


def row(values: dict) -> list[str]:
    series = simulate(values)
    indices = score_series(series, values)
    t, error = series["t"], np.abs(series["target"] - series["speed"]) / KMH
    worst = int(np.argmax(error))
    timetable = run_timetable(values)
    if timetable is not None:
        stations = worst_stations(run_journey(series, values, timetable))
        stop, arrival = stations[WORST_STOP], stations[WORST_ARRIVAL]
    else:
        stop, arrival = (indices.get(name, math.nan)  # NaN: a run without a stop
                         for name in ("stopping_error", "running_time_error"))
    return [f"{error[worst]:.3f}", f"{t[worst]:.1f}", f"{error[t < FIRST_SECONDS].max():.3f}",
            f"{error[t >= 1.0].max():.3f}", signed(stop, 3), signed(arrival, 1),
            f"{indices['max_jerk']:.3f}"]


def signed(value: float, decimals: int) -> str:
    return "-" if math.isnan(value) else f"{value:+.{decimals}f}"


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenarios", nargs="+", metavar="SCENARIO",
                        help="scenarios with a position-indexed plan from standstill")
    args = parser.parse_args()
    try:
        runs = {(name, target): prepare(name, overrides) for name in args.scenarios
                for target, overrides in TARGETS.items()}
    except ScenarioError as exc:
        _cli.fail(str(exc))
    print("| scenario | target | max abs(e) km/h | at s | first 10 s | after 1 s | stop m "
          "(journey: worst) | arrival s (journey: worst) | max jerk m/s^3 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for (name, target), values in runs.items():
        print(f"| {name} | {target} | " + " | ".join(row(values)) + " |", flush=True)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
