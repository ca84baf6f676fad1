#!/usr/bin/env python3
"""The train learned on board (profile.replan, core/targets/replan.py): seed004-metro-ato
driven by a light quick-actuator, a nominal and a heavy slow-actuator train, with what the
ATO knows of
the load either nothing (no load weighing: the mass prior 1 +- estimator.mass_sigma
0.15) or a load weighing that reads 15 % light (trusted to its stated 3 %); the on-board
estimator on (the mass, the running resistance and, with estimator.lag_sigma 0.2, the
actuator's lag), its mass bound re-planning the ato curve.

    python scripts/learned_on_board.py
    python scripts/learned_on_board.py --figure /tmp/learned.png

Prints a Markdown table per run: the estimates at the stop against the real train (mass,
resistance and lag, their sigma), their mean absolute error while moving, the re-plans
made (time, the new plan's mass), and the run's tracking, stop and arrival; draws the
mass estimate with its +-1 sigma band, the mass each plan was made for and the real
mass, and the resistance scale and the lag factor (+-1 sigma) against the real ones
(--figure, PNG).
"""

from __future__ import annotations

from pathlib import Path

import _cli
import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config.context import planned_mass
from ato_nodes.core.control.estimation import ESTIMATED_FACTORS
from ato_nodes.core.run.loop import simulate
from ato_nodes.results.journeys import score_run
from ato_nodes.studies.runner import Variant, prepare_variants

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "seed004-metro-ato"
TRAINS = {  # label -> the real train's factors
    "light, quick (m 0.85, lag 0.8)": {"plant.mass_factor": 0.85, "plant.lag_factor": 0.8},
    "nominal": {},
    "heavy, slow (m 1.3, lag 1.3, resistance 1.2)": {
        "plant.mass_factor": 1.3, "plant.lag_factor": 1.3, "plant.resistance_factor": 1.2},
}
KNOWLEDGE = {  # label -> what the ATO knows of the load, and the re-plans on
    "no load weighing": {"train.load_weighing": False, "train.mass_reading": 1.0,
                         "estimator.mass_sigma": 0.15},
    "weighed 15 % light": {"train.load_weighing_bias": -0.15},
}
ON_BOARD = {"estimator.enabled": True, "profile.replan.enabled": True,
            "estimator.lag_sigma": 0.2}


def parse_args():
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--figure", type=Path,
                        default=ROOT / "docs/results/estimation/learned-on-board.png")
    args = parser.parse_args()
    if args.figure.suffix.lower() != ".png":
        _cli.fail(f"--figure must name a .png file, got {args.figure}")
    return args


def learned(values: dict) -> dict:
    """The run's series, its re-plans and indices."""
    replans = []
    series = simulate(values, replans=replans)
    return {"series": series, "replans": replans, "indices": score_run(series, values),
            "values": values, "real": {name: values[factor] for name, (_, factor) in
                                       ESTIMATED_FACTORS.items()}}


def planned_masses(result: dict) -> np.ndarray:
    """The mass the plan in force was made for, at every step."""
    t = result["series"]["t"]
    masses = np.full(len(t), max(planned_mass(result["values"]), 1.0))
    for replan in result["replans"]:
        masses[t > replan.time] = replan.mass
    return masses


def table_row(knowledge: str, train: str, result: dict) -> str:
    series, indices = result["series"], result["indices"]
    moving = series["speed"] > 0.0
    cells = [knowledge, train]
    for name, real in result["real"].items():
        sigma = ESTIMATED_FACTORS[name][0]
        error = series[name] / real - 1.0
        cells += [f"{series[name][-1]:.3f} +- {series[sigma][-1]:.3f} (real {real:g})",
                  f"{100 * np.abs(error[moving]).mean():.1f}"]
    made = "; ".join(f"{replan.time:.1f} s: {replan.mass:.3f}" for replan in result["replans"])
    cells += [f"{planned_masses(result)[0]:.3f}", made or "none",
              f"{indices['max_abs_error_kmh']:.3f}", f"{indices['stopping_error']:+.3f}",
              f"{indices['running_time_error']:+.1f}"]
    return "| " + " | ".join(cells) + " |"


def plot(results: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, axes = plt.subplots(len(KNOWLEDGE), 3, figsize=(17, 7.5), sharex=True)
    for row, knowledge in zip(axes, KNOWLEDGE, strict=True):
        for colour, train in enumerate(TRAINS):
            result = results[knowledge, train]
            series, t = result["series"], result["series"]["t"]
            mass, sigma = series["mass_factor"], series["mass_sigma"]
            row[0].plot(t, mass, color=f"C{colour}", lw=1.2, label=train)
            row[0].fill_between(t, mass - sigma, mass + sigma, color=f"C{colour}", alpha=0.15,
                                lw=0)
            row[0].plot(t, planned_masses(result), color=f"C{colour}", lw=1.0, ls="--")
            row[0].axhline(result["real"]["mass_factor"], color=f"C{colour}", lw=0.6, ls=":")
            row[1].plot(t, series["resistance_scale"], color=f"C{colour}", lw=1.2)
            row[1].axhline(result["real"]["resistance_scale"], color=f"C{colour}", lw=0.6,
                           ls=":")
            lag, sigma = series["lag_factor"], series["lag_sigma"]
            row[2].plot(t, lag, color=f"C{colour}", lw=1.2)
            row[2].fill_between(t, lag - sigma, lag + sigma, color=f"C{colour}", alpha=0.15,
                                lw=0)
            row[2].axhline(result["real"]["lag_factor"], color=f"C{colour}", lw=0.6, ls=":")
            for replan in result["replans"]:
                row[0].axvline(replan.time, color=f"C{colour}", lw=0.6, alpha=0.6)
        row[0].set(title=f"{knowledge}: mass (dashed: the plan's)", ylabel="over the nominal",
                   ylim=(0.7, 1.6))
        row[1].set(title=f"{knowledge}: running resistance", ylabel="over the nominal",
                   ylim=(0.5, 2.0))
        row[2].set(title=f"{knowledge}: actuator lag", ylabel="over the nominal",
                   ylim=(0.5, 1.6))
        for axis in row:
            axis.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper left")
    for axis in axes[-1]:
        axis.set_xlabel("t, s")
    figure.suptitle(f"{SCENARIO}: the train learned on board (estimates +-1 sigma; dotted: "
                    "the real train), the ato curve re-planned (vertical lines)")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def main() -> None:
    args = parse_args()
    try:
        runs = prepare_variants({(knowledge, train): Variant(SCENARIO, {
            **ON_BOARD, **known, **real})
            for knowledge, known in KNOWLEDGE.items() for train, real in TRAINS.items()})
        args.figure.parent.mkdir(parents=True, exist_ok=True)
    except ScenarioError as exc:
        _cli.fail(str(exc))
    except OSError as exc:
        _cli.fail(f"--figure {args.figure}: {exc.strerror}")
    results = {key: learned(values) for key, values in runs.items()}
    print("| the ATO knows | real train | mass at the stop | mean abs error % | resistance "
          "at the stop | mean abs error % | lag at the stop | mean abs error % | planned at "
          "departure | re-plans (t: mass) | max abs(e) km/h | stop m | arrival s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for (knowledge, train), result in results.items():
        print(table_row(knowledge, train, result))
    try:
        plot(results, args.figure)
    except OSError as exc:
        _cli.fail(f"--figure {args.figure}: {exc.strerror or exc}")
    print(f"\nfigure: {args.figure}")


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
