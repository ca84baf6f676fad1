#!/usr/bin/env python3
"""Where the ATO believes its train is, against where it is: the on-board localisation
(ato_nodes/core/control/localisation.py) over a run of seed004-metro-ato, the ATO driving
on its estimate, for several sets of sensors, and the stop each gives.

    python scripts/localisation_accuracy.py
    python scripts/localisation_accuracy.py --seed 3 --figure /tmp/localisation.png

Each case runs in-process with odometry.enabled and the sensors it names (SENSORS, the
rest the schema's: a 0.84 m wheel, 200 pulses a turn, its diameter 0.5 % off, 1 sigma,
drawn with odometry.seed = --seed); prints a Markdown table (the located position's
largest error and at the stop, its stated sigma at the stop, the located speed's largest
error, the true stop error) and draws the position's error over the run with its
+-3 sigma band (--figure, PNG).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import _cli
import numpy as np

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.base.units import MS_TO_KMH
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.train.lines import line_of
from ato_nodes.studies.runner import Variant, prepare_variants

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "seed004-metro-ato"
BALISES = {"odometry.balise_spacing": 500.0}
BEACONS = {"odometry.beacon_distances": "150,50,20,5", "odometry.beacon_accuracy": 0.02}
# every sensor but the tachometer off: each case names what it has (the scenario's own
# sensor set, ato-on-board's, would otherwise stand in for those it leaves out)
TACHOMETER = {"odometry.radar": False, "odometry.accelerometer": False,
              "odometry.balise_spacing": 0.0, "odometry.beacon_distances": ""}
SENSORS = {  # label -> the odometry.* values of the case
    "tachometer, radar, accelerometer, balises, beacons": {
        **TACHOMETER, **BALISES, **BEACONS, "odometry.radar": True,
        "odometry.accelerometer": True},
    "tachometer, accelerometer, balises, beacons": {
        **TACHOMETER, **BALISES, **BEACONS, "odometry.accelerometer": True},
    "tachometer, balises, beacons": {**TACHOMETER, **BALISES, **BEACONS},
    "tachometer, balises (no beacons)": {**TACHOMETER, **BALISES},
    "tachometer alone": TACHOMETER,
}


def parse_args() -> argparse.Namespace:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--seed", type=int, default=1, help="odometry.seed (default 1)")
    parser.add_argument("--figure", type=Path,
                        default=ROOT / "docs" / "results" / "localisation" / "accuracy.png")
    return parser.parse_args()


def main() -> None:
    args = parse_args()
    try:
        variants = prepare_variants({label: Variant(SCENARIO, {
            "odometry.enabled": True, "odometry.seed": args.seed, **sensors})
            for label, sensors in SENSORS.items()}, [])
    except ScenarioError as exc:
        _cli.fail(str(exc))
    runs = {label: simulate(values) for label, values in variants.items()}
    print("| sensors | max abs(position error) m | at the stop m | its sigma m "
          "| max abs(speed error) km/h | stop error m |")
    print("|---|---|---|---|---|---|")
    for label, series in runs.items():
        error = series["located_position"] - series["position"]
        speed = (series["measured_speed"] - series["speed"]) * MS_TO_KMH
        mark = series["position"][-1] - line_of(variants[label]).stop_position
        print(f"| {label} | {np.abs(error).max():.3f} | {error[-1]:+.3f} | "
              f"{series['position_sigma'][-1]:.3f} | {np.abs(speed).max():.3f} | {mark:+.3f} |")
    _plot(runs, args.figure)
    print(f"figure: {args.figure}")


def _plot(runs: dict, figure: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(len(runs), 1, figsize=(9, 2.1 * len(runs)), sharex=True)
    for axis, (label, series) in zip(axes, runs.items(), strict=True):
        error = series["located_position"] - series["position"]
        band = 3.0 * series["position_sigma"]
        axis.fill_between(series["position"], -band, band, color="0.85", label="+-3 sigma")
        axis.plot(series["position"], error, lw=1.0, label="located - true")
        marks = np.isfinite(series["mark_reading"])
        axis.plot(series["position"][marks], error[marks], "k|", ms=8, label="a mark read")
        limit = max(float(np.abs(error).max()) * 1.3, 0.1)
        axis.set_ylim(-limit, limit)
        axis.set_ylabel("m")
        axis.set_title(label, fontsize=9)
    axes[0].legend(fontsize=7, loc="upper left")
    axes[-1].set_xlabel("true position m")
    fig.tight_layout()
    figure.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(figure, dpi=110)


if __name__ == "__main__":
    main()
