#!/usr/bin/env python3
"""Accuracy of the on-board estimator of the train's mass, running resistance and
actuator lag (ato_nodes/core/control/estimation.py) on light, nominal and heavy trains, on
a running resistance 20 % off and on an actuator 30 % slow or quick, for
seed004-metro-ato and seed003-maglev-ato.

    python scripts/estimator_accuracy.py
    python scripts/estimator_accuracy.py --weighing-seed 3 --figure /tmp/accuracy.png

Each case runs in-process with the real train changed (plant.mass_factor,
plant.resistance_factor, plant.lag_factor; the controller keeps the nominal train), then
the estimator runs over what the ATO had of it (the commands it sent, the measured
speeds; the lag estimated, estimator.lag_sigma 0.2), its prior the load weighing of the
real mass (--weighing-error, 1 sigma; --weighing-seed). Prints
a Markdown table (final errors; errors averaged over the time the train moves, absolute)
and draws the mass factor's, the resistance scale's and the lag factor's errors against
the real train over time with the +-1 sigma band (--figure, PNG).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import _cli
import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.control.estimation import (ESTIMATED_FACTORS, PARAMETERS, estimate_series,
                                               estimator_of, load_weighing)
from ato_nodes.core.config.schema import SPEC_BY_NAME
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.train.lines import line_of
from ato_nodes.core.train.plant import TrainParameters
from ato_nodes.studies.runner import Variant, prepare_variants

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ("seed004-metro-ato", "seed003-maglev-ato")
WEIGHING_ERROR = SPEC_BY_NAME["train.load_weighing_error"].default
LAG_SIGMA = 0.2  # the lag estimated (estimator.lag_sigma; off by default)
CASES = {  # label -> the real train's plant.* factors
    "light (m 0.85)": {"plant.mass_factor": 0.85},
    "nominal": {},
    "heavy (m 1.3)": {"plant.mass_factor": 1.3},
    "resistance +20 %": {"plant.resistance_factor": 1.2},
    "resistance -20 %": {"plant.resistance_factor": 0.8},
    "slow actuator (lag 1.3)": {"plant.lag_factor": 1.3},
    "quick actuator (lag 0.7)": {"plant.lag_factor": 0.7},
}
ESTIMATES = {  # name -> (the estimate (estimation.ESTIMATED_FACTORS), words, plot limit %)
    "mass": ("mass_factor", "mass factor", 8),
    "resistance": ("resistance_scale", "resistance scale", 25),
    "lag": ("lag_factor", "lag factor", 25),
}


def parse_args() -> argparse.Namespace:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--weighing-error", type=float, default=WEIGHING_ERROR,
                        help="load weighing's relative error, 1 sigma (default "
                             f"train.load_weighing_error's {WEIGHING_ERROR:g})")
    parser.add_argument("--weighing-seed", type=int, default=4,
                        help="seed of the load weighing's error (default 4)")
    parser.add_argument("--figure", type=Path,
                        default=ROOT / "docs/results/estimation/accuracy.png")
    args = parser.parse_args()
    if not (math.isfinite(args.weighing_error) and 0.0 <= args.weighing_error <= 0.5):
        _cli.fail(f"--weighing-error must be within 0 and 0.5, got {args.weighing_error}")
    if not 0 <= args.weighing_seed < 2**31:
        _cli.fail(f"--weighing-seed must be within 0 and 2^31 - 1, got {args.weighing_seed}")
    if args.figure.suffix.lower() != ".png":
        _cli.fail(f"--figure must name a .png file, got {args.figure}")
    return args


def estimated(values: dict, reading: float, error: float) -> dict[str, np.ndarray]:
    """The run's series and the estimator's over them, the errors against the real train."""
    series = simulate(values)
    estimator = {spec.name: spec.default for spec in PARAMETERS}
    estimator["train.load_weighing_error"] = error
    estimator["estimator.lag_sigma"] = LAG_SIGMA
    line = line_of(values)
    settings, state = estimator_of(estimator, TrainParameters.from_values(values),
                                   values["run.period"], reading, line,
                                   values["plant.initial_position"])
    rows, _ = estimate_series(settings, state, series["command"], series["measured_speed"],
                              fast=True)
    result = {"t": series["t"], "moving": series["speed"] > 0.0}
    for name, (column, _, _) in ESTIMATES.items():
        sigma, factor = ESTIMATED_FACTORS[column]
        result[f"{name}_error"] = rows[column] / values[factor] - 1.0
        result[f"{name}_sigma"] = rows[sigma] / values[factor]
    return result


def table_row(scenario: str, label: str, result: dict) -> str:
    moving = result["moving"]
    cells = [scenario, label]
    for name in ESTIMATES:
        error = result[f"{name}_error"]
        cells += [f"{100 * error[-1]:+.2f}", f"{100 * result[f'{name}_sigma'][-1]:.2f}",
                  f"{100 * np.abs(error[moving]).mean():.2f}"]
    return "| " + " | ".join(cells) + " |"


def plot(results: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, axes = plt.subplots(len(SCENARIOS), len(ESTIMATES), figsize=(18, 7.5),
                                sharex="row")
    for row, scenario in zip(axes, SCENARIOS, strict=True):
        for axis, (name, (_, what, limit)) in zip(row, ESTIMATES.items(), strict=True):
            for colour, label in enumerate(CASES):
                result = results[scenario, label]
                error, sigma = 100 * result[f"{name}_error"], 100 * result[f"{name}_sigma"]
                axis.plot(result["t"], error, color=f"C{colour}", lw=1.2, label=label)
                axis.fill_between(result["t"], error - sigma, error + sigma,
                                  color=f"C{colour}", alpha=0.12, lw=0)
            axis.axhline(0.0, color="k", lw=0.6)
            axis.set(title=f"{scenario}: {what}", xlabel="t, s",
                     ylabel="estimate / real - 1, %", ylim=(-limit, limit))
            axis.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper right")
    figure.suptitle("On-board estimator: error against the real train, +-1 sigma band")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def main() -> None:
    args = parse_args()
    try:
        runs = prepare_variants({(scenario, label): Variant(scenario, real)
                                 for scenario in SCENARIOS for label, real in CASES.items()})
    except ScenarioError as exc:
        _cli.fail(str(exc))
    try:
        args.figure.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        _cli.fail(f"--figure {args.figure}: {exc.strerror}")
    results = {}
    for (scenario, label), values in runs.items():
        reading = load_weighing(values["plant.mass_factor"], args.weighing_error,
                                args.weighing_seed)
        results[scenario, label] = estimated(values, reading, args.weighing_error)
    print("| scenario | real train | " + " | ".join(
        f"{name} error final % | sigma % | mean abs %" for name in ESTIMATES) + " |")
    print("|---|---|" + "---|---|---|" * len(ESTIMATES))
    for scenario, label in results:
        print(table_row(scenario, label, results[scenario, label]))
    try:
        plot(results, args.figure)
    except OSError as exc:
        _cli.fail(f"--figure {args.figure}: {exc.strerror or exc}")
    print(f"\nload weighing error {args.weighing_error:g} (1 sigma), seed "
          f"{args.weighing_seed}; figure: {args.figure}")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
