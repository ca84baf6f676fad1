#!/usr/bin/env python3
"""Robustness of a controller: one scenario over a seeded spread of real trains.

    python scripts/robustness.py seed004-metro-tuned --samples 50 --out bags/robust-metro

Each sample draws, uniformly in the given ranges, the real train's mass (its load,
as a share of the nominal plant.mass), running resistance and actuator lag (shares of
the nominal ones), a speed-sensor noise seed and a load-weighing seed; the controller
and the profile keep the nominal train (plant.mass_factor, plant.resistance_factor,
plant.lag_factor are the plant node's alone), at the weighed mass when the scenario
weighs its load (train.load_weighing). Runs in-process in --workers processes; prints
and writes (robustness.json, robustness.png) the median and worst of max abs(e), p95
abs(e), abs(stopping error), max jerk over 1 s and ITAE, and how many samples keep
within 1 km/h, stop within 0.1 m and arrive within 5 s of the planned time. On a
journey (profile.kind journey) also the worst stop and arrival over its stations
(core/scoring/journey.py) and how many samples stop within 0.1 m and arrive within
5 s of the timetable at every station (a station missed or not reached: neither).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import _cli
import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.results.journeys import WORST_ARRIVAL, WORST_STOP, score_with_journey
from ato_nodes.studies.runner import (Variant, check_counts, in_pool, prepare_variants,
                                      write_outputs)

INDICES = (  # key, heading, worst is the largest of
    ("max_abs_error_kmh", "max abs(e) km/h"),
    ("p95_abs_error_kmh", "p95 abs(e) km/h"),
    ("abs_stopping_error", "abs(stop error) m"),
    ("max_jerk", "max jerk (1 s) m/s^3"),
    ("itae", "ITAE"),
    (WORST_STOP, "journey: worst stop m"),
    (WORST_ARRIVAL, "journey: worst arrival s"),
)
WITHIN = (  # key, bound, what the count says
    ("max_abs_error_kmh", 1.0, "within 1 km/h"),
    ("abs_stopping_error", 0.1, "stops within 0.1 m"),
    ("abs_running_time_error", 5.0, "arrivals within 5 s"),
    (WORST_STOP, 0.1, "every stop of the journey within 0.1 m"),
    (WORST_ARRIVAL, 5.0, "every arrival of the journey within 5 s"),
)


def span(text: str, name: str) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in text.split(":"))
    except ValueError:
        _cli.fail(f"--{name} expects LOW:HIGH, got {text!r}")
    if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
        _cli.fail(f"--{name} needs 0 < LOW <= HIGH, got {text!r}")
    return low, high


def parse_args() -> argparse.Namespace:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("scenario")
    parser.add_argument("--samples", type=int, default=50)
    parser.add_argument("--mass", default="0.85:1.3", help="mass range, share of the nominal "
                        "(default 0.85:1.3, empty to crush load)")
    parser.add_argument("--resistance", default="0.8:1.2", help="resistance range (+-20 %%)")
    parser.add_argument("--lag", default="0.7:1.3", help="actuator lag range (+-30 %%)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    return parser.parse_args()


def draw_trains(ranges: dict, samples: int, seed: int) -> list[dict]:
    """Each sample's real train: a share of each nominal value, uniform in its range,
    a speed-sensor noise seed and a load-weighing seed (from a stream of their own, so
    the trains are those of the same seed before the load weighing)."""
    rng, weighing = np.random.default_rng(seed), np.random.default_rng([seed, 1])
    return [{**{name: float(rng.uniform(low, high)) for name, (low, high) in ranges.items()},
             "plant.noise_seed": int(rng.integers(0, 2**31 - 1)),
             "train.load_weighing_seed": int(weighing.integers(0, 2**31 - 1))}
            for _ in range(samples)]


def sample_result(draw: dict, indices: dict) -> dict:
    """The sample's draw and the indices of INDICES it has."""
    result = {**draw, **{key: float(indices[key]) for key, _ in INDICES if key in indices}}
    if "stopping_error" in indices:
        result["abs_stopping_error"] = abs(float(indices["stopping_error"]))
    if "running_time_error" in indices:
        result["running_time_error"] = float(indices["running_time_error"])
        result["abs_running_time_error"] = abs(result["running_time_error"])
    return result


def counts(results: list[dict]) -> dict[str, int]:
    """How many samples keep each bound of WITHIN (of those that have its index)."""
    return {text: sum(1 for r in results if key in r and r[key] <= bound)
            for key, bound, text in WITHIN if any(key in r for r in results)}


def main() -> None:
    args = parse_args()
    try:
        check_counts(samples=args.samples, workers=args.workers, seed=args.seed)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    options = {"plant.mass_factor": "mass", "plant.resistance_factor": "resistance",
               "plant.lag_factor": "lag"}
    ranges = {name: span(getattr(args, option), option) for name, option in options.items()}
    draws = draw_trains(ranges, args.samples, args.seed)
    try:  # both ends of each range inside the schema's range, then every sample
        prepare_variants({f"--{options[name]} {getattr(args, options[name])}, {end}":
                          Variant(args.scenario, {name: bound}) for name, bounds in ranges.items()
                          for end, bound in zip(("LOW", "HIGH"), bounds, strict=True)}, args.set)
        runs = prepare_variants({f"sample {number}": Variant(args.scenario, draw)
                                 for number, draw in enumerate(draws)}, args.set)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    _cli.new_directory(args.out)
    outcomes = in_pool(score_with_journey, runs.values(), args.workers)
    results = [{**sample_result(draw, indices),
                "train.mass_reading": values["train.mass_reading"]}  # what the ATO knew
               for draw, indices, values in zip(draws, outcomes, runs.values(), strict=True)]
    summary = {}
    for key, heading in INDICES:
        column = [r[key] for r in results if key in r]
        if column:
            summary[key] = {"median": float(np.median(column)), "worst": float(max(column))}
            print(f"{heading:24s} median {summary[key]['median']:.4g}  worst "
                  f"{summary[key]['worst']:.4g}")
    kept = counts(results)
    print("; ".join(f"{text}: {count} of {len(results)}" for text, count in kept.items()))
    write_outputs(args.out, "robustness", report={
        "scenario": args.scenario, "set": args.set, "ranges": ranges, "seed": args.seed,
        "summary": summary, "within": kept, "samples": results})
    plot(results, args.out / "robustness.png", args.scenario)
    print(f"{args.samples} samples; outputs: {args.out}/robustness.json, robustness.png")


def plot(results: list[dict], path: Path, scenario: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    factors = ("plant.mass_factor", "plant.resistance_factor", "plant.lag_factor")
    figure, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for axis, name in zip(axes, factors, strict=True):
        axis.plot([r[name] for r in results], [r["max_abs_error_kmh"] for r in results], "o",
                  ms=3)
        axis.set(xlabel=name.split(".")[1].replace("_", " "))
        axis.grid(alpha=0.3)
    axes[0].set_ylabel("max abs(e), km/h")
    figure.suptitle(f"{scenario}: max tracking error over {len(results)} real trains")
    figure.tight_layout()
    figure.savefig(path, dpi=110)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
