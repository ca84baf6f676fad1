#!/usr/bin/env python3
"""Seed 001's comparison through the real stack: GPC on the adaptive LSSVM model, on
the fixed LSSVM, on the mechanistic model and on the linear multi-model, beside the
project's tuned Han ADRC and PID, on the seed001-crh380al run.

    python scripts/compare_seed001.py --out bags/compare-seed001

Each variant runs through the stack (recorded, scored from its bag) and in-process;
the two must agree bit for bit. Two conditions: the nominal train, and a train whose
running resistance is 30 % above the nominal (plant.resistance_factor = 1.3: the
plant alone changes; every model was identified, or is parametrised, on the
nominal train). Prints and writes (comparison.md, comparison.json) max |e|
(km/h), ITAE, RMS of the command change per step (N/kN, smoothness), traction/brake
switches, max jerk over 1 s, traction energy and stopping error.
"""

from __future__ import annotations

from pathlib import Path

import _cli
import numpy as np

from ato_nodes import jsontext
from ato_nodes.bagio import read_run
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from ato_nodes.launch import run_checked

VARIANTS = {  # name: (scenario, overrides)
    "GPC, adaptive LSSVM": ("seed001-crh380al", []),
    "GPC, LSSVM without correction": ("seed001-crh380al", ["gpc.correction=false"]),
    "GPC, mechanistic model": ("seed001-crh380al", ["gpc.prediction=mechanistic"]),
    "GPC, linear multi-model": ("seed001-crh380al", ["gpc.prediction=multimodel"]),
    "Han ADRC (tuned)": ("seed001-crh380al-adrc", []),
    "PID (tuned)": ("seed001-crh380al-pid", []),
}
CONDITIONS = {"nominal": [], "resistance +30 %": ["plant.resistance_factor=1.3"]}
COLUMNS = (  # key, heading, format
    ("max_abs_error_kmh", "max abs(e) km/h", "{:.3f}"),
    ("p95_abs_error_kmh", "p95 abs(e) km/h", "{:.3f}"),
    ("itae", "ITAE", "{:.0f}"),
    ("command_change_rms", "RMS du N/kN", "{:.3f}"),
    ("switch_count", "switches", "{:d}"),
    ("max_jerk", "max jerk m/s^3", "{:.3f}"),
    ("traction_energy_kwh", "traction kWh", "{:.1f}"),
    ("stopping_error", "stop error m", "{:+.2f}"),
    ("bit_identical", "stack = in-process", "{}"),
)


def run_variant(values: dict, bag: Path) -> dict:
    """Through the stack, then in-process; indices from the bag."""
    try:
        indices, identical = run_checked(values, bag)
    except RuntimeError as exc:
        _cli.fail(str(exc), 1)
    run = read_run(bag)
    indices["command_change_rms"] = float(np.sqrt(np.mean(np.diff(run.series["command"]) ** 2)))
    indices["bit_identical"] = "yes" if identical else "NO"
    return indices


def table(results: dict) -> list[str]:
    lines = ["| variant | " + " | ".join(h for _, h, _ in COLUMNS) + " |",
             "|---|" + "---|" * len(COLUMNS)]
    for name, indices in results.items():
        cells = [fmt.format(indices[key]) if key in indices else "" for key, _, fmt in COLUMNS]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("--out", type=Path, required=True, help="directory to create")
    parser.add_argument("--duration", type=float, help="simulated seconds (default: the "
                        "scenario's whole run)")
    args = parser.parse_args()
    _cli.new_directory(args.out)
    args.out.mkdir()
    extra = [f"run.duration={args.duration}"] if args.duration else []
    report, markdown = {}, []
    for number, (condition, change) in enumerate(CONDITIONS.items()):
        results = {}
        for variant, (name, (scenario, overrides)) in enumerate(VARIANTS.items()):
            values = apply_overrides(load_scenario(scenario), [*overrides, *change, *extra])
            bag = args.out / f"condition{number}-variant{variant}"
            results[name] = run_variant(values, bag)
            print(f"{condition}: {name}: max |e| {results[name]['max_abs_error_kmh']:.3f} km/h "
                  f"({bag})", flush=True)
        report[condition] = results
        markdown += [f"## {condition}", "", *table(results), ""]
    (args.out / "comparison.json").write_text(jsontext.dumps(report, indent=2))
    (args.out / "comparison.md").write_text("\n".join(markdown))
    print("\n".join(markdown))


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
